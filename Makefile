# The README's two commands: `make report` (the main job) and `make test` (the test suite).
# Both set up .venv from the pinned requirements on a fresh machine first.
.PHONY: setup report gate test lint

setup:
	@scripts/bootstrap

report: setup
	.venv/bin/harness report

gate: setup
	.venv/bin/harness gate

test: setup
	@scripts/test-deps
	.venv/bin/python -m pytest -q -n 2 --dist worksteal

lint: setup
	.venv/bin/ruff check harness problems implementations tests benchmarks

# Performance tracking (benchmarks/, asv.conf.json; see scripts/nightly and scripts/bench).
.PHONY: nightly perf-check bench

nightly: setup
	@scripts/nightly

perf-check: setup
	@scripts/nightly check

bench: setup
	@scripts/bench
