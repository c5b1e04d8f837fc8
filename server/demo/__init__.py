"""Built-in demo game client."""
