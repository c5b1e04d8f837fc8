"""Motion overview of a captured human action (papers/motion-overview-human-actions.md).

Entry point: `camdirector.precompute.overview.pipeline.plan_overview`.
"""
