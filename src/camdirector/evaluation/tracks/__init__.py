"""Evaluation of the TRACKS rig: actor routes on a level, the frame-aware measure, and the paper's
comparison of our camera graph with probabilistic roadmaps (Section 6.2)."""
