# roadview: every target works from a fresh clone on a machine with only Python 3.11 and pip.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
SHARED ?= ../shared/data
DATA := data

.PHONY: install data calibrate train demo test lint bench clean

install: $(STAMP)

# The versions the README's figures were measured with (constraints.txt), for figures that repeat.
$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[dev]'
	touch $(STAMP)

data: $(STAMP)
	$(BIN)/roadview data --source $(SHARED) --dest $(DATA)

calibrate: data
	$(BIN)/roadview calibrate --images $(DATA)/camera_cal --board 9x6 --out camera_cal/dashcam.json

# The verifier also learns hard negatives, mined from the wild clips without vehicles when they
# are there (their first 60 %; the rest measures the result) by the model trained without them.
WILD := $(SHARED)/wild
NEGATIVE_CLIPS := $(wildcard $(WILD)/rural_2lane_wet.mp4 $(WILD)/night_highway_istock.mp4)
# On a dark road the 64 px models are checked by the dark verifier instead, which also learns the
# false alarms of dimmed, grainy copies of the same clips (`mine --dusk`).
# The 32 px model reads the smallest windows (cars 3-4 % of the height), with its own verifier;
# the low-resolution model reads pictures under 540 rows (trained also on compressed copies).
# Monochrome footage is read by twins of the 64 and 32 px models and their verifiers trained
# on the patches without colour (the verifiers' hard negatives mined from the clips so).
train: data
	$(BIN)/roadview train --data $(DATA) --out vehicles/models/default.npz
	$(BIN)/roadview train --data $(DATA) --out vehicles/models/small.npz --patch 32
	$(BIN)/roadview train --data $(DATA) --out vehicles/models/lowres.npz --degrade
	$(BIN)/roadview train --data $(DATA) --out vehicles/models/grey.npz --grey
	$(BIN)/roadview train --data $(DATA) --out vehicles/models/grey_small.npz --patch 32 --grey
ifneq ($(NEGATIVE_CLIPS),)
	$(BIN)/roadview mine $(NEGATIVE_CLIPS) --out output/hard_negatives --every 1
	$(BIN)/roadview train --data $(DATA) --out vehicles/models/verifier.npz \
		--hard-negatives output/hard_negatives
	$(BIN)/roadview train --data $(DATA) --out vehicles/models/small_verifier.npz --patch 32 \
		--hard-negatives output/hard_negatives
	$(BIN)/roadview mine $(NEGATIVE_CLIPS) --out output/dusk_negatives --every 1 --dusk
	$(BIN)/roadview train --data $(DATA) --out vehicles/models/dark_verifier.npz \
		--hard-negatives output/hard_negatives --hard-negatives output/dusk_negatives
	$(BIN)/roadview mine $(NEGATIVE_CLIPS) --out output/grey_negatives --every 1 --grey \
		--model vehicles/models/grey.npz
	$(BIN)/roadview train --data $(DATA) --out vehicles/models/grey_verifier.npz --grey \
		--hard-negatives output/grey_negatives
	$(BIN)/roadview train --data $(DATA) --out vehicles/models/grey_small_verifier.npz \
		--patch 32 --grey --hard-negatives output/grey_negatives
else
	@echo "no wild clips in $(WILD): the verifiers are not retrained"
endif

demo: data
	$(BIN)/roadview process $(DATA)/videos/test_video.mp4 -o output/test_video_roadview.mp4 \
		--json output/test_video_roadview.jsonl

test: data
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

bench: data
	$(BIN)/python -m bench

clean:
	rm -rf $(VENV) $(DATA) output .mypy_cache .ruff_cache .pytest_cache
