# roadview: every target works from a fresh clone on a machine with only Python 3.11 and pip.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
SHARED ?= ../shared/data
DATA := data

.PHONY: install data calibrate train demo test lint bench clean

install: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

data: $(STAMP)
	$(BIN)/roadview data --source $(SHARED) --dest $(DATA)

calibrate: data
	$(BIN)/roadview calibrate --images $(DATA)/camera_cal --board 9x6 --out camera_cal/dashcam.json

train: data
	$(BIN)/roadview train --data $(DATA) --out vehicles/models/default.npz

demo: data
	$(BIN)/roadview process $(DATA)/videos/test_video.mp4 -o output/test_video_roadview.mp4 \
		--json output/test_video_roadview.jsonl

test: data
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy

bench: data
	$(BIN)/python -m bench

clean:
	rm -rf $(VENV) $(DATA) output .mypy_cache .ruff_cache .pytest_cache
