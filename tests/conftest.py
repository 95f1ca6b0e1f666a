import os

# Drake's package cache goes to a temp dir in tests (never the user's cache, never the network).
os.environ.setdefault("XDG_CACHE_HOME", "/tmp/corn_drake_test_cache")
