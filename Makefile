# Two commands on a fresh machine:  make demo  (the main job)  and  make test.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
OUT    ?= out/demo

.PHONY: demo test schema clean

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
	$(VENV)/bin/ladder check scenarios/two_finger_triangle.toml --out $(OUT)/two_finger_triangle.check.json
	@for f in scenarios/*.toml; do $(VENV)/bin/ladder check $$f --json > /dev/null && echo "ok: $$f"; done
	@echo "outputs: $(OUT)/two_finger_triangle.check.json"

test: $(VENV)/.installed-test
	$(PY) -m pytest

schema: $(VENV)/.installed
	$(VENV)/bin/ladder schema --out scenarios/scenario.schema.json

clean:
	rm -rf $(VENV) out .pytest_cache
