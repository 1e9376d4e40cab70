# warpsky: two commands on a fresh machine (times on a 2-core CPU: README, "Quickstart").
#   make demo   make data (every shipped stage's data), render usd_scenes/cumulus.usda to out/cumulus.0001.exr (+ PNG)
#   make test   run the test suite on the CPU (make test-fast: without the tests marked slow)
PYTHON ?= python3
VENV   ?= .venv
PY      = $(VENV)/bin/python
STAMP   = $(VENV)/.installed-$(shell cat pyproject.toml | cksum | cut -d' ' -f1)

# The times make help quotes, on a 2-core CPU: written from docs/timings.json by tools/measure_timings.py --apply.
TIMING_DEMO            = 25 s
TIMING_DEMO_COLD       = 107 s
TIMING_DATA            = 7.5 s
TIMING_TEST            = 7 min 53 s
TIMING_TEST_TESTS      = 1092
TIMING_TEST_FAST       = 2 min 34 s
TIMING_TEST_FAST_TESTS = 905
TIMING_STORM           = 2 min 53 s
TIMING_VALLEY_FOG      = 2 min 40 s
TIMING_SUNBEAMS        = 3 min 50 s
TIMING_GALLERY         = 12 min 7 s

.PHONY: demo test test-fast lint bench venv data clean help storm storm-data stratocumulus stratocumulus-anim \
	cumulus-wind family family-thick scenery-family terrain valley-fog sunbeams sundogs gallery cycles-env \
	simulate-storm storm-procedural

help:
	@echo "make demo               - install into $(VENV), make data, render the demo cumulus to out/ (with a PNG;"
	@echo "                          $(TIMING_DEMO) on 2 CPU cores with Warp's kernels cached, $(TIMING_DEMO_COLD) the first time)"
	@echo "make test               - install into $(VENV), make the sample data and run every test on the CPU ($(TIMING_TEST_TESTS) tests, $(TIMING_TEST) on 2 cores)"
	@echo "make test-fast          - the tests not marked slow (pytest -m 'not slow'; $(TIMING_TEST_FAST_TESTS) tests, $(TIMING_TEST_FAST))"
	@echo "make lint               - ruff"
	@echo "make bench              - run evaluation/benchmarks/bench_single_scatter.py (cuda too when present)"
	@echo "make venv               - create $(VENV) and install warpsky with all extras (redone when pyproject changes)"
	@echo "make data               - generate the data every stage in usd_scenes/ references, in data/ (the cumulus,"
	@echo "                          storm, stratocumulus and sundog fields and the terrain; $(TIMING_DATA) on 2 CPU cores)"
	@echo "make family             - generate the 24-stage validation family (seed 2026) in data/family"
	@echo "make family-thick       - generate the 12-stage thick family (optical depth 100-1000, seed 2027) in"
	@echo "                          data/family_thick"
	@echo "make scenery-family     - generate the 16-stage scenery family (terrain with valley fog, a height-field deck"
	@echo "                          with haze, cumulus cut by a ridge, fog under a stratocumulus layer; seed 2028) in"
	@echo "                          data/scenery_family"
	@echo "make cumulus-wind       - 48 frames of the cumulus in wind (usd_scenes/cumulus_wind.usda) to out/"
	@echo "make stratocumulus      - stratocumulus over water, sand and snow, radiosity on and off, to out/"
	@echo "make stratocumulus-anim - the 48-frame advected stratocumulus sequence to out/stratocumulus_anim/"
	@echo "make storm-data         - the storm's per-frame NanoVDB fields in data/storm/"
	@echo "make storm              - the simulated storm (make simulate-storm, cached by its inputs), 48 frames of"
	@echo "                          two shots (rainbow, storm from the side) at 256 wide with slicing, contact sheets, preview"
	@echo "                          ($(TIMING_STORM) on 2 CPU cores once simulated and the optics tables cached)"
	@echo "make simulate-storm     - grow the storm with the cloud solver (warpsky simulate: 128x128x64 cells, 48"
	@echo "                          frames) to out/simulate/; redone when its options, STORM_SOUNDING or the solver"
	@echo "                          change (docs/guide/simulate.md gives its time)"
	@echo "make storm-procedural   - the procedural storm (usd_scenes/storm.usda: rainbow and anvil-halo shots)"
	@echo "make terrain            - the seeded 4 km fractal terrain mesh data/terrain.usda (hills, a north-south valley)"
	@echo "make valley-fog         - 48 frames of morning fog drifting in the terrain's valley (Biri 2002) to"
	@echo "                          out/valley_fog/ with a contact sheet, each frame's paths to the 5% target or"
	@echo "                          --time-budget 10 ($(TIMING_VALLEY_FOG) on 2 CPU cores)"
	@echo "make sunbeams           - sunbeams through gaps in a Max 1986 cloud deck over the terrain, lighting the"
	@echo "                          haze, to out/sunbeams/: frame 1 (exact), 4 drifting frames and a contact sheet,"
	@echo "                          frame 1 with Max's thickness rule, time-budgeted paths"
	@echo "                          ($(TIMING_SUNBEAMS) on 2 CPU cores)"
	@echo "make sundogs            - cirrostratus of oriented plates and columns at sunset: sundogs, arcs, labelled PNG"
	@echo "make gallery            - every shipped stage's hero frame to docs/gallery/ and docs/gallery.md, with each"
	@echo "                          command, time and error estimate ($(TIMING_GALLERY) on 2 CPU cores)"
	@echo "make cycles-env         - Blender's bpy 5.0 (Cycles) in its own Python 3.11 environment .venv-cycles, for"
	@echo "                          evaluation/benchmarks/bench_cycles.py (BPY_WHEELS=DIR: a folder with the wheel)"
	@echo "make clean              - remove out/, data/ and .pytest_cache"
	@echo "make help               - this list"

venv: $(STAMP)

$(STAMP): pyproject.toml
	@echo "make venv: installing warpsky and its dependencies into $(VENV) (about 2.3 GB; a few minutes when pip downloads them)"
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --progress-bar off -e ".[dev,denoise,compare,farm,preview,color,textures,weather]"
	rm -f $(VENV)/.installed-*
	touch $@

# The data the shipped stages reference (usd_scenes/*.usda). Each command is the one a missing file's error names
# (warpsky/usd/generated_data.py, with python for $(PY)); a test checks the two agree.
DATA = data/cumulus.nvdb data/storm/.complete data/stratocumulus/.complete data/sundogs/.complete data/terrain.usda

data/cumulus.nvdb: tools/make_cumulus.py $(STAMP)
	@echo "make data: the demo cumulus field data/cumulus.nvdb (a few seconds)"
	$(PY) tools/make_cumulus.py --out data

data/stratocumulus/.complete: tools/make_stratocumulus.py $(STAMP)
	@echo "make data: the stratocumulus thickness and ground maps in data/stratocumulus/ (a second)"
	$(PY) tools/make_stratocumulus.py --out data
	touch $@

data/sundogs/.complete: tools/make_sundogs.py $(STAMP)
	@echo "make data: the sundogs' two ice sheets in data/sundogs/ (a second)"
	$(PY) tools/make_sundogs.py --out data/sundogs
	touch $@

data: $(DATA)
	@echo "make data: every stage in usd_scenes/ has its data in data/"

# The validation family: 24 seeded stages, tune and test halves (warpsky bench error-vs-time --family data/family).
data/family/family.json: evaluation/scripts/make_validation_family.py evaluation/family_stages.py \
		evaluation/family_shapes.py $(STAMP)
	$(PY) evaluation/scripts/make_validation_family.py --out data/family

family: data/family/family.json

# The thick family: 12 seeded storms, dense decks and cumulus of peak optical depth 100-1000, at 64 x 64.
data/family_thick/family.json: evaluation/scripts/make_validation_family.py evaluation/family_stages.py \
		evaluation/family_shapes.py $(STAMP)
	$(PY) evaluation/scripts/make_validation_family.py --profile thick --out data/family_thick --seed 2027 --count 12

family-thick: data/family_thick/family.json

# The scenery family: 16 seeded terrain stages (fog, a deck with haze, a ridge cloud, fog under a stratocumulus layer)
# at 96 x 64, for the path tracer's references of terrain, analytic fog, height-field decks and layers over them
# (warpsky bench error-vs-time --family data/scenery_family).
data/scenery_family/family.json: evaluation/scripts/make_scenery_family.py evaluation/scenery_family.py \
		evaluation/family_stages.py evaluation/family_shapes.py $(STAMP)
	$(PY) evaluation/scripts/make_scenery_family.py --out data/scenery_family --seed 2028 --count 12 --layered 4

scenery-family: data/scenery_family/family.json

demo: $(STAMP) $(DATA)
	$(VENV)/bin/warpsky render usd_scenes/cumulus.usda out/cumulus.####.exr --frames 1 --png

test: $(STAMP) $(DATA)
	$(PY) -m pytest -q

test-fast: $(STAMP) $(DATA)
	$(PY) -m pytest -q -m "not slow"

lint: $(STAMP)
	$(VENV)/bin/ruff check warpsky evaluation tests tools

bench: $(STAMP) data/cumulus.nvdb
	$(PY) evaluation/benchmarks/bench_single_scatter.py

cumulus-wind: $(STAMP) data/cumulus.nvdb
	$(VENV)/bin/warpsky render usd_scenes/cumulus_wind.usda out/cumulus_wind.####.exr --frames 1:48 --png

# Stratocumulus over water, sand and snow (Bouthors 2006), rendered by warpsky render with radiosity on and off;
# stratocumulus-anim: the 48-frame advected sequence (Neyret 2003), one EXR + PNG per frame.
SC_RENDER = $(VENV)/bin/warpsky render --png --exposure 1

stratocumulus: $(STAMP) data/stratocumulus/.complete
	$(SC_RENDER) usd_scenes/stratocumulus.usda out/stratocumulus-radiosity-on.exr --res 384
	$(SC_RENDER) usd_scenes/stratocumulus.usda out/stratocumulus-radiosity-off.exr --res 384 \
		--set stratiform.radiosity=0
	$(PY) tools/make_stratocumulus.py --radiosity-light out

stratocumulus-anim: $(STAMP) data/stratocumulus/.complete
	$(SC_RENDER) usd_scenes/stratocumulus_anim.usda out/stratocumulus_anim/sc.####.exr --res 256

# The storm, grown by the cloud solver (warpsky simulate: 128x128x64 cells of 500 m x 250 m, 48 frames over 40
# minutes), simulated once per sounding, options and solver source (the stamp's name holds the options' checksum),
# then two shots rendered as batches (resumable: rerun to finish an interrupted one): the rainbow shot (the stage's
# RainbowCam, sun at its back) and the storm from 30 km (/World/StormCam, following it), a contact sheet per shot
# and a 3-D preview.
# Slicing, because the default technique's storm frame still costs minutes on a CPU (STORM_TECHNIQUE=hybrid picks
# it). STORM_WORKERS=0 renders in-process. STORM_SOUNDING=FILE grows it from a CM1 input_sounding.
# The procedural storm (tools/make_storm.py, usd_scenes/storm.usda): make storm-data, make storm-procedural.
STORM_WORKERS   ?= 2
STORM_RES       ?= 256
# Previews and contact sheets of the simulated storm at a fixed exposure (a white surface facing the sun at 1.4,
# half a stop over it): the frame's own exposure lifts a storm's shaded anvil and base to pale grey.
STORM_EXPOSURE  ?= 0.5
STORM_TECHNIQUE ?= slicing
STORM_BATCH      = --technique $(STORM_TECHNIQUE) $(if $(filter 0,$(STORM_WORKERS)),,--workers $(STORM_WORKERS))
STORM_SOUNDING  ?=
STORM_SIMULATE  ?= --frames 48 --minutes 40 --time-step 10
STORM_SIM       := out/simulate
STORM_SIM_STAMP := $(STORM_SIM)/.complete-$(shell echo '$(STORM_SIMULATE) $(STORM_SOUNDING)' | cksum | cut -d' ' -f1)

data/storm/.complete: tools/make_storm.py $(STAMP)
	@echo "make data: the storm's 48 frames of cloud, rain, snow and ice in data/storm/ (a few seconds)"
	$(PY) tools/make_storm.py --out data/storm --frames 48
	touch $@

storm-data: data/storm/.complete

$(STORM_SIM_STAMP): $(STAMP) $(STORM_SOUNDING) $(wildcard warpsky/simulate/*.py)
	rm -f $(STORM_SIM)/.complete-*
	$(VENV)/bin/warpsky simulate --out $(STORM_SIM) $(if $(STORM_SOUNDING),--sounding $(STORM_SOUNDING)) \
		$(STORM_SIMULATE)
	touch $@

simulate-storm: $(STORM_SIM_STAMP)

storm: $(STORM_SIM_STAMP)
	$(VENV)/bin/warpsky render $(STORM_SIM)/storm.usda out/storm/rainbow.####.exr --res $(STORM_RES) $(STORM_BATCH) \
		--exposure $(STORM_EXPOSURE)
	$(VENV)/bin/warpsky render $(STORM_SIM)/storm.usda out/storm/side.####.exr --camera /World/StormCam \
		--res $(STORM_RES) $(STORM_BATCH) --exposure $(STORM_EXPOSURE)
	$(VENV)/bin/warpsky contact-sheet out/storm/rainbow.####.exr -o out/storm/rainbow_sheet.png
	$(VENV)/bin/warpsky contact-sheet out/storm/side.####.exr -o out/storm/side_sheet.png
	$(VENV)/bin/warpsky preview $(STORM_SIM)/storm.usda -o out/storm/preview.png --frame 40

storm-procedural: $(STAMP) data/storm/.complete
	$(VENV)/bin/warpsky render usd_scenes/storm.usda out/storm_procedural/rainbow.####.exr --res $(STORM_RES) \
		$(STORM_BATCH)
	$(VENV)/bin/warpsky render usd_scenes/storm.usda out/storm_procedural/anvil.####.exr --camera /World/AnvilCam \
		--res $(STORM_RES) $(STORM_BATCH)

# Terrain, valley fog (Biri 2002) and sunbeams (Max 1986): one terrain mesh, two stages that reference it.
data/terrain.usda: tools/make_terrain.py $(STAMP)
	@echo "make data: the 4 km terrain mesh data/terrain.usda of the valley fog and sunbeams (a few seconds)"
	$(PY) tools/make_terrain.py --seed 1 --valley-angle 90 --resolution 257 --out data/terrain.usda

terrain: data/terrain.usda

valley-fog: $(STAMP) data/terrain.usda
	$(VENV)/bin/warpsky render usd_scenes/valley_fog.usda out/valley_fog/valley_fog.####.exr --png --time-budget 10
	$(VENV)/bin/warpsky contact-sheet out/valley_fog/valley_fog.####.exr -o out/valley_fog/sheet.png

sunbeams: $(STAMP) data/terrain.usda
	$(VENV)/bin/warpsky render usd_scenes/sunbeams.usda out/sunbeams/sunbeams.####.exr --frames 1 --png \
		--time-budget 120
	$(VENV)/bin/warpsky render usd_scenes/sunbeams.usda out/sunbeams/drift.####.exr --frames 1,17,33,48 --res 192 --png \
		--time-budget 20
	$(VENV)/bin/warpsky contact-sheet out/sunbeams/drift.####.exr -o out/sunbeams/drift_sheet.png
	$(VENV)/bin/warpsky render usd_scenes/sunbeams.usda out/sunbeams/max-rule.####.exr --frames 1 --png \
		--set deck.mode=max --time-budget 20

# The gallery: one hero frame per shipped stage (tools/make_gallery.py runs each warpsky render command).
gallery: $(STAMP) $(DATA) $(STORM_SIM_STAMP)
	$(PY) tools/make_gallery.py

# bpy 5.0 pins Python 3.11 and numpy < 2 (.venv has numpy 2), and brings 1 GB of Blender: its own environment.
CYCLES_VENV ?= .venv-cycles
PYTHON311   ?= python3.11
cycles-env: $(CYCLES_VENV)/.installed

$(CYCLES_VENV)/.installed:
	test -x $(CYCLES_VENV)/bin/python || $(PYTHON311) -m venv $(CYCLES_VENV)
	$(CYCLES_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(CYCLES_VENV)/bin/python -m pip install --quiet $(if $(BPY_WHEELS),--find-links $(BPY_WHEELS)) "bpy==5.0.0" "numpy<2"
	touch $@

clean:
	rm -rf out data .pytest_cache

# Sundogs: oriented ice plates and columns in a cirrostratus sheet at sunset (single scattering: the sheet is thin),
# the frame as EXR + PNG and a copy with each arc labelled where its closed form puts it.
sundogs: $(STAMP) data/sundogs/.complete
	$(VENV)/bin/warpsky render usd_scenes/sundogs.usda out/sundogs/sundogs.####.exr --frames 1 --png \
		--technique single_scatter --res 768x512
	$(PY) tools/label_halos.py usd_scenes/sundogs.usda out/sundogs/sundogs.0001.png out/sundogs/sundogs_labelled.png
