"""The harness: matrix runner, metrics, timing, gates, results store and the `frictionbench` CLI."""
