"""Recorded matches of real games: importers that turn a game's demo file into a match file
(evaluation/match/match_file.py), and players that stream a recorded match, so `eval-match` and
the MATCH rig can direct real play."""
