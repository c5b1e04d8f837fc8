"""Matches for the casting director (issue 12): the match file format (match_file.py) and the bot
match simulator behind `camdirector match-sim` (sim.py)."""
