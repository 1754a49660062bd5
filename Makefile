# The two commands the README leads with: `make demo` and `make test`.
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-$(shell cat pyproject.toml constraints.txt | sha1sum | cut -c1-12)

.PHONY: demo test bench system-deps

# pytest-xdist hands out whole files: a module-scoped fixture (a campaign several tests read) is
# then built once, not once on each worker that got one of its tests
DIST   := --dist loadfile

system-deps:
	@tools/system-deps

$(STAMP): pyproject.toml constraints.txt
	@tools/system-deps
	@test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -c constraints.txt -e '.[dev,pdf]'
	@rm -f $(VENV)/.installed-* && touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/gyrostand demo

test: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/pytest -n auto $(DIST) -m "not slow"  # pytest-xdist: one worker per core

# The long end-to-end tests (tests/conftest.py SLOW_FILES): CI's second stage
.PHONY: test-slow
test-slow: $(STAMP)
	$(VENV)/bin/pytest -n auto $(DIST) -m slow

bench: $(STAMP)
	@for b in bench/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

# The two-process NMEA 2000 campaign over udp_multicast on the host (real time; not in CI's budget)
.PHONY: test-processes
test-processes: $(STAMP)
	GYROSTAND_PROCESS_TESTS=1 $(VENV)/bin/pytest -m slow tests/devices/test_n2k_processes.py \
		tests/devices/test_cia402_processes.py tests/acquisition/test_cia402_live.py

# The `socketcan` tests on a real SocketCAN bus: in a small Linux VM with vcan0 (tools/vcan-vm,
# docs/socketcan.md). On a machine that has vcan0 itself: .venv/bin/pytest -m socketcan
.PHONY: test-socketcan
test-socketcan: $(STAMP)
	tools/vcan-vm run $(VENV)/bin/pytest -m socketcan --durations=5 tests/socketcan
