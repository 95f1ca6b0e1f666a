"""The encoder benchmarks: the CORN encoder against PointNet (latency, peak memory, each in
a fresh process) and the contact-data generator's samples/s."""
