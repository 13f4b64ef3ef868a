"""hvloc: hierarchical vision-based localization for UAV landing.

Importing this package is cheap (no OpenCV/torch at import): the heavy modules are imported
by name, e.g. ``from hvloc.localizer import HierarchicalLocalizer``.
"""
__version__ = "0.1.0"
