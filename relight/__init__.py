"""relight: light direction and colour from one image (Sial et al.), verified with Mitsuba 3.

Start with ``relight --help``; the conventions live in :mod:`relight.frames`.
"""
__version__ = "0.1.0"
