"""Identification: one weighted least-squares engine; the papers' methods are configurations."""
