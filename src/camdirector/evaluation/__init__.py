"""Evaluation of the director: scenarios, measurement independent of the rig, the papers comparisons."""
