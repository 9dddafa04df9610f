"""Planning: which poses to measure (observability indices, candidates, selection)."""
