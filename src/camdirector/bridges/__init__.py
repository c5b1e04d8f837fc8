"""Bridges from a game's own live feed into a RIG_MATCH session (`camdirector cast`): CS2's Game
State Integration (gsi.py, gsi_server.py, gsi_tracks.py, gsi_cast.py) and, out, CS2's console
(netcon.py); QuakeWorld over QTV (qtv.py); the session loop they share (live_session.py)."""
