# The two commands of README.md: `make demo` (main job) and `make test` (whole suite).
# Both create .venv on first use and reuse it afterwards.
.PHONY: venv venv-jazzy demo test test-jazzy bench bench-nodes bench-drivers lint clean

venv:
	@scripts/setup_venv.sh

demo: venv
	scripts/ros_env.sh .venv/bin/python -m continuum_statics demo

test: venv
	scripts/ros_env.sh --private .venv/bin/python -m pytest -q test

# The second route: the same suite on ROS 2 Jazzy wheels (requirements-jazzy.txt, .venv-jazzy).
venv-jazzy:
	@VENV=.venv-jazzy REQUIREMENTS=requirements-jazzy.txt scripts/setup_venv.sh

test-jazzy: venv venv-jazzy
	scripts/ros_env.sh --private .venv-jazzy/bin/python -m pytest -q test

bench: venv
	scripts/ros_env.sh .venv/bin/python -m continuum_statics bench

bench-nodes: venv
	scripts/ros_env.sh --private .venv/bin/python -m continuum_statics bench --nodes

# Dynamixel backend against the Protocol 2.0 emulator on a simulated 1 Mbps wire: sync write +
# sync read cycle and the highest cable_driver publish_rate, for 4 and 9 servos.
bench-drivers: venv
	scripts/ros_env.sh --private .venv/bin/python -m continuum_statics.tools.driver_bench

lint: venv
	.venv/bin/ruff check .

clean:
	rm -rf .venv .venv-jazzy build install log *.egg-info
