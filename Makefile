# Two commands on a fresh machine:  make demo  (the main job)  and  make test.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
OUT    ?= out/demo

# Lint and format check (CI runs it before the tests):  make lint
.PHONY: demo test lint schema bench bench-doc paper clean clean-cache

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(VENV)/.installed: pyproject.toml | $(PY)
	$(PY) -m pip install --quiet -e .
	touch $@

$(VENV)/.installed-test: pyproject.toml | $(PY)
	$(PY) -m pip install --quiet -e ".[test]"
	touch $@ $(VENV)/.installed

demo: $(VENV)/.installed
	@mkdir -p $(OUT)
	$(VENV)/bin/ladder check scenarios/two_finger_triangle.toml --out $(OUT)/two_finger_triangle.check.json
	@for f in scenarios/*.toml; do $(VENV)/bin/ladder check $$f --json > /dev/null && echo "ok: $$f"; done
	@echo "simulating the paper's scene up the model family (ladder says so first when it must compile the kernels)"
	@for rung in kinematic quasistatic-rigid dynamic-compliant; do \
		$(VENV)/bin/ladder simulate scenarios/two_finger_triangle.toml --model $$rung --param v1=0.8 \
			--json --plot $(OUT)/two_finger_triangle.$$rung.png > $(OUT)/two_finger_triangle.$$rung.json || exit $$?; \
		echo "$$rung: $$(python3 -c "import json,sys; d=json.load(open('$(OUT)/two_finger_triangle.$$rung.json')); print(d['outcome'], 'at t =', round(d['t'], 4), 's,', d['status'], '| x3 =', round(d['state']['triangle.x'], 4))")"; \
	done
	$(VENV)/bin/ladder plan scenarios/two_finger_triangle.toml --param v1=0.8 --out $(OUT)/plan
	@echo "outputs: $(OUT)/ (check summary, one simulation JSON and Fig. 4 plot per rung, and plan/: plan.json, report.json, a plot per rung)"

# The viewer's browser test drives Debian's chromium (Playwright's own browser download is not
# used): make test installs it when it is missing (as root, as CI runs; otherwise it says how).
CHROMIUM ?= /usr/bin/chromium

$(CHROMIUM):
	@if [ "$$(id -u)" != 0 ]; then echo "make test: the browser test needs $(CHROMIUM): run  sudo apt-get install chromium  (or make test CHROMIUM=/path/to/chromium)"; exit 1; fi
	apt-get update -qq
	DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium

test: $(VENV)/.installed-test $(CHROMIUM)
	LADDER_CHROMIUM=$(CHROMIUM) $(PY) -m pytest

lint: $(VENV)/.installed-test
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

schema: $(VENV)/.installed
	$(VENV)/bin/ladder schema --out scenarios/scenario.schema.json

# The paper's Figs. 4-5 reproduced: sweeps, plots and docs/paper-reproduction.md (about 3 minutes on two cores).
paper: $(VENV)/.installed
	$(PY) -m planner.paper --out docs/paper --doc docs/paper-reproduction.md

bench: $(VENV)/.installed-test
	$(PY) -m pytest -m slow --benchmark-enable -s

# ladder bench: work-precision, throughput, scaling, ladder vs flat over 20 seeds -> docs/benchmarks.md
# (about twenty minutes, mostly the spatial scenes' flat runs; PLANNING=two_finger_triangle,four_finger_grasp:
# a few minutes).
PLANNING ?= two_finger_triangle,four_finger_grasp,box_push_3d,box_rotate_3d
bench-doc: $(VENV)/.installed
	$(VENV)/bin/ladder bench --planning $(PLANNING) --out docs/bench --doc docs/benchmarks.md --readme README.md

# numba's cache of the compiled kernels, beside the sources (stamped by all of models/, so an
# edit there recompiles them by itself: models/kernel_cache.py): delete it.
clean-cache:
	find models -name '*.nbi' -delete -o -name '*.nbc' -delete

clean: clean-cache
	rm -rf $(VENV) out .pytest_cache
