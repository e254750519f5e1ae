"""The `sds` command: `cli` is the entry point, `commands/` one module per subcommand (its
arguments, one call into `sds_workflows` or the launcher, its exit code)."""
