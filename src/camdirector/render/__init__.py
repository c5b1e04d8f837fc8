"""The render process: the monitors' pictures, painted off the frame path (main.py), from the
snapshots a worker takes of its sessions (snapshots.py) and sends through its handle (monitor.py)."""
