"""Evaluation of the TORIC rig: scenarios streamed through a real session (run.py), the measure
independent of the rig (measure.py), and the paper's comparison of every visibility mode on its
benchmark scenes (suite.py, Section 6), behind `camdirector eval` (cli.py)."""
