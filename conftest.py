"""Repository-wide pytest set-up.

The classroom notebooks (``notebooks/*.ipynb``, run by nbval with ``--nbval-lax``) read
``UAM_FAST`` through :func:`uam_studio.classroom.fast_mode`. Tests run them in fast mode unless the
caller sets the variable (``UAM_FAST=0 python -m pytest notebooks`` runs the full-size versions).
It is set here, at import time, before any kernel starts, so every notebook kernel inherits it;
``tests/test_notebooks.py`` checks that a kernel really sees it.
"""

import os

os.environ.setdefault("UAM_FAST", "1")
