"""Web adapter: the only code that imports fastapi."""
