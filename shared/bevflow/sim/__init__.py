"""Simulation: people walking through a site, what each camera sees of them, and detector noise."""
