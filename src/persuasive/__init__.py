"""persuasive: persuasive trajectory planning with an adaptive leader-follower game.

A robot (an autonomous vehicle) predicts a human driver's reaction with a leader-follower game
whose roles adapt, and plans with a branch MPC that shapes the human's intention under a chance
constraint on safety (He, Dong, Li, MECC 2025).
"""

__version__ = "0.1.0"
