"""The paper's studies.

The Table 2 open loop, its reproduction study, the paper's numerics and the open-loop
optimiser.
"""
