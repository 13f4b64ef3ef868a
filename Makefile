# The two commands the README opens with.  Each installs what it needs (scripts/bootstrap.sh).
VENV ?= .venv
OUT ?= out/demo
export PYOPENGL_PLATFORM ?= osmesa

.PHONY: demo test install bench clean

install:
	@VENV=$(VENV) scripts/bootstrap.sh

demo: install
	$(VENV)/bin/hvloc demo --out $(OUT)

test: install
	$(VENV)/bin/python -m pytest -q -n auto --dist worksteal

bench: install
	$(VENV)/bin/python -m benchmarks.speed

clean:
	rm -rf out .pytest_cache
