"""Scenes, trajectories, IMU, degradations and the dataset format (writer and reader).

Importing this package is cheap; pyrender/OpenGL load only when a renderer is created.
"""
