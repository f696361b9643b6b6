"""The small street of the data tests (the masks' evaluation reads its ground-truth masks)."""

from street_fixtures import small_street  # noqa: F401
