"""Studies built on many runs: the comparison of planners and humans (``compare``).

The paper's own tables live in :mod:`persuasive.experiments`; parameter sweeps in
:mod:`persuasive.sweep`.
"""
