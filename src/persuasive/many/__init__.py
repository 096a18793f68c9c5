"""Many vehicles: the AV among N vehicles at a four-way unsignalised junction
(docs/method.md §15).

- :mod:`.junction`: the junction as data (routes, arrivals, right of way, variants);
- :mod:`.world`: the vehicles and conflict tables and the N-vehicle closed loop;
- :mod:`.measures`: the wait-for graph, deadlocks, waiting, throughput, delays, PET;
- :mod:`.study`: many seeds, each with and without the AV, on worker processes;
- :mod:`.joint`: the AV's one plan against every human (and which planner the AV gets);
- :mod:`.rule`: Li et al.'s pairwise leader-follower AV (``lfg-rule``);
- :mod:`.sumo`: the junction and its arrivals in Eclipse SUMO, SUMO's own driver as the AV.
"""
