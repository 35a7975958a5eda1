"""Shared pytest configuration: a deterministic, deadline-free hypothesis profile."""

import os

from hypothesis import settings

settings.register_profile("mpcform", deadline=None, derandomize=True, max_examples=30)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "mpcform"))
