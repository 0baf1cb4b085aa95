"""Benchmarks and studies, apart from the solver: throughput and effects (throughput), parallel
scaling (scaling), what accuracy costs (accuracy), the per-kernel profile (phase_profile), the
benchmark block they share (block) and longer studies (studies). Each prints its figures and,
last, one JSON line; ``pmpm bench ...`` dispatches them (cli)."""
