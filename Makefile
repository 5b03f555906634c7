# Convenience aliases; the README's two commands are scripts/run_main.sh and scripts/run_tests.sh.
.PHONY: run test test-fast setup bench clean
run:
	bash scripts/run_main.sh
test:
	bash scripts/run_tests.sh
test-fast:
	bash scripts/run_tests.sh --fast
setup:
	bash scripts/setup.sh
bench: setup
	bash scripts/run_benchmarks.sh
clean:
	bash -c 'source scripts/paths.sh && rm -rf build .stamps out "$$UQ_WS"'
