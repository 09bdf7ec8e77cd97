"""ladder's physics: scenarios, geometry, contact kinematics, solvers and the model family.

`models` never imports `planner`.
"""
