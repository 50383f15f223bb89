"""Scenarios: WHAT is simulated (scenario model, loader and validation, mesh catalogue, suites)."""
