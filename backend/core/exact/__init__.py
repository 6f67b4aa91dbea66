"""Exact inference over the template formulas of 2 to 10 objects without enumerating formulas."""
