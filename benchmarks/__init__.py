"""Metrics, suites, sweeps, leaderboard, reports and speed benchmarks."""
