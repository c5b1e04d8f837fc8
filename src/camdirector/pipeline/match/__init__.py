"""The MATCH rig: a director that chooses whom to show among many players from game events, using
the broadcast delay (issue 12). rig.py ties the stages together over any registered director (director_contract.py,
director_registry.py); settings.py holds the tuning."""
