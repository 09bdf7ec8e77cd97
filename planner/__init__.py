"""ladder's planning side: OMPL adapters, the ladder pipeline, sweeps and the CLI."""
