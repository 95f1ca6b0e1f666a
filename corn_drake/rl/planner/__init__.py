"""A planning policy with the simulator as its model (privileged): beam search over contact
primitives of several kinds (kinds.py), simulated on the env itself (search.py)."""
