"""Pure learner: LTL, clause space, priors, exact belief, PUnS planning, queries, sessions (numpy only)."""
