# The two commands of README.md: `make demo` (main job) and `make test` (whole suite).
# Both create .venv on first use and reuse it afterwards.
.PHONY: venv venv-jazzy demo test test-jazzy bench bench-nodes lint clean

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

lint: venv
	.venv/bin/ruff check .

clean:
	rm -rf .venv .venv-jazzy build install log *.egg-info
