"""Storage adapter: the only code that imports sqlalchemy."""
