# topdress: the two commands of the README are `make demo` and `make test`.
# Both create .venv and install what they need on first use. `make check` is the fast tier:
# lint, types, the C tests and every test that needs no browser, no QEMU and no wall-clock demo.

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
CSRC := $(wildcard ecu/src/*.c ecu/src/gen/*.c ecu/src/gen/*.h ecu/include/*.h src/topdress/sim/csrc/* ecu/isobus/src/*.c ecu/isobus/src/gen/*.c ecu/isobus/src/gen/*.h ecu/isobus/include/*.h) src/topdress/ecu/_build.py src/topdress/isobus/_build.py
DURATION ?= 30

.PHONY: demo test check ctest ctest-san pytest pytest-fast lint lint-c lint-py bench sysdeps browser qemu office screenshots clean firmware interop

$(STAMP): pyproject.toml setup.py $(CSRC)
	PYTHON=$(PYTHON) bash scripts/sysdeps.sh python
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/topdress demo --start --duration $(DURATION)

sysdeps:
	bash scripts/sysdeps.sh ctest

browser:
	bash scripts/sysdeps.sh browser

# the emulated firmware's tests (tests/test_ecu_qemu.py): qemu-system-arm and the firmware's compiler
qemu:
	bash scripts/sysdeps.sh qemu

# the farm office's tests and bench (tests/test_office*.py): PostgreSQL and PostGIS
office:
	bash scripts/sysdeps.sh office

# The ECU firmware for the STM32F405/407 (docs/firmware.md): an image per board header
# (build/fw/topdress-ecu-stm32f4.elf for the generic 8 MHz board, build/fw-BOARD/ for the others)
# and the emulator build (build/fw-qemu/), each with its flash, RAM and worst stack figures.
FW_BOARDS := generic8 olimex_e407 olimex_p407
firmware:
	bash scripts/sysdeps.sh firmware
	for b in $(FW_BOARDS); do $(MAKE) --no-print-directory -f ecu/ports/stm32f4/firmware.mk BOARD=$$b || exit 1; done
	$(MAKE) --no-print-directory -f ecu/ports/stm32f4/firmware.mk VARIANT=qemu

# The C tests, instrumented for line coverage (printed; at least 90 % of the core's and the
# ports' lines).
ctest: sysdeps
	cmake -S ecu -B build/ecu -DCMAKE_BUILD_TYPE=Debug -DTD_COVERAGE=ON >/dev/null
	cmake --build build/ecu -j2
	find build/ecu -name '*.gcda' -delete
	ctest --test-dir build/ecu --output-on-failure
	gcovr -r ecu build/ecu -e 'ecu/tests/' -e 'ecu/.*/tests/' -e '.*/gen/.*' \
	    -o build/ecu/coverage.txt --print-summary --fail-under-line 90

# The same tests under ASan+UBSan (make test only).
ctest-san: sysdeps
	cmake -S ecu -B build/ecu-san -DCMAKE_BUILD_TYPE=Debug -DTD_SANITIZE=ON >/dev/null
	cmake --build build/ecu-san -j2
	ctest --test-dir build/ecu-san --output-on-failure

# cppcheck and clang-tidy (.clang-tidy) on the C code: a finding fails the build.
lint-c: sysdeps
	bash scripts/lint_c.sh

lint-py: $(STAMP)
	$(BIN)/ruff check src tests bench
	$(BIN)/ruff format --check src tests bench
	$(BIN)/mypy

lint: lint-c lint-py

# The whole suite with Python line coverage (printed; at least 85 %) and the slowest 15 tests.
# Four workers on two cores: the slowest tests mostly wait on a browser, a demo or QEMU.
pytest: $(STAMP) browser qemu office
	$(BIN)/python -m pytest -q --durations=15 --cov=topdress --cov-report=term:skip-covered \
	    --cov-fail-under=85 -n 4

# The fast tier's tests: no browser, no QEMU, no wall-clock demo (markers in pyproject.toml).
pytest-fast: $(STAMP) office
	$(BIN)/python -m pytest -q --durations=15 -m "not browser and not qemu and not wallclock" -n 2

# The display's screenshots in docs/ (both languages), from its end-to-end test.
screenshots: $(STAMP) browser
	TOPDRESS_SCREENSHOTS=docs $(BIN)/python -m pytest -q tests/test_display_browser.py tests/test_display_cab.py

# the ISOBUS layer against stacks nobody here wrote (can-j1939, isoxml), alone (docs/isobus.md)
interop: $(STAMP)
	$(BIN)/python -m pytest -q -m interop tests/test_isobus_interop_j1939.py tests/test_isobus_ddop.py tests/test_isobus_agiso_replay.py tests/test_isobus_tcserver.py tests/test_isobus_tc_j1939.py tests/test_isobus_tc_isoxml.py tests/test_isobus_tc_protocol.py tests/test_isobus_tc_faults.py tests/test_terminal_agiso.py

# One part after the other: the wall-clock tests in pytest (real-time demos, pulled adapters, a
# browser) want the two cores to themselves; beside the C builds (even at a lower priority) a
# command period or a keystroke was lost under the load, and the whole took no less time.
test: ctest ctest-san lint pytest

check: ctest lint pytest-fast

# Every script's figures also go to bench/figures.json and docs/figures.md (bench/figures.py).
BENCHES := ecu_bench.py fused_lag_bench.py field_speed_bench.py fw_bench.py isobus_bench.py sim_bench.py terminal_bench.py \
           can_bench.py maps_bench.py display_bench.py longday_bench.py office_bench.py
bench: SHELL := /bin/bash
bench: $(STAMP) browser office
	set -o pipefail; for b in $(BENCHES); do \
	    $(BIN)/python bench/$$b | $(BIN)/python bench/figures.py $$b || exit 1; done

clean:
	rm -rf build $(VENV) src/topdress/ecu/_core*.so src/topdress/ecu/_core.c src/topdress/isobus/_isobus*.so src/topdress/isobus/_isobus.c
