"""The small street of the data tests (the masks stage trains its first reference on it)."""

from street_fixtures import small_street, street_copy  # noqa: F401
