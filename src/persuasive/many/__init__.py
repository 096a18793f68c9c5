"""Many vehicles: the AV among N vehicles at a four-way unsignalised junction
(docs/method.md §15).

- :mod:`.junction`: the junction as data (routes, arrivals, right of way, variants);
- :mod:`.world`: the vehicles and conflict tables and the N-vehicle closed loop;
- :mod:`.measures`: the wait-for graph, deadlocks, waiting, throughput, delays, PET;
- :mod:`.study`: many seeds, each with and without the AV, on worker processes.
"""
