"""femubench.bench: suites, runner, results store, reports and the command line."""
