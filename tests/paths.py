"""Where the tests find their data: tests/data in the repository, and ../shared/data beside it."""

from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
TEST_DATA = REPOSITORY / "tests" / "data"
# Real recordings kept beside the repository, not in it; tests that read them skip when absent.
SHARED_DATA = REPOSITORY.parent / "shared" / "data"
