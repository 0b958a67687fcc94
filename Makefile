# orokit: the two entry points are `make report` (main pipeline) and `make test`.
#
# Both create .venv if missing and install orokit with its dev extras once
# (stamp .venv/.installed, redone when pyproject.toml changes).
#
# Adding a pipeline stage (later issues): write a pattern rule whose target is ONE
# file under reports/<stage>/<name>/ and whose prerequisites are real files from
# earlier stages, call only `$(OROKIT) ...` in its recipe, list the outputs in a
# variable built from $(DATASETS), and append that variable to REPORT_OUTPUTS.
# Every target writes one file atomically, so `make -j2 report` is safe and a rerun
# only redoes what changed.

SHELL := /bin/bash
.DELETE_ON_ERROR:
# keep intermediate files of pattern-rule chains (a twin's hillshade.png marks its folder complete)
.PRECIOUS: reports/roundtrip/%/hillshade.png reports/roundtrip/relief/%/hillshade.png
.SUFFIXES:

PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
INSTALLED := $(VENV)/.installed
OROKIT := $(BIN)/orokit
PYTEST_ARGS ?=

# Real data: copied from a local mirror when OROKIT_DATA_MIRROR is set (or when
# ../shared/data exists beside the repository), else downloaded from the manifest
# URLs into the cache (OROKIT_DATA_DIR, default ~/.cache/orokit). Hashes are always checked.
ifeq ($(origin OROKIT_DATA_MIRROR),undefined)
  ifneq ($(wildcard ../shared/data/README.md),)
    export OROKIT_DATA_MIRROR := $(abspath ../shared/data)
  endif
endif

# progress bars of the long stages (classification, twins) update at most every 10 s, so that the
# two bars of `make -j2 report` stay readable in a terminal and in a log
export TQDM_MININTERVAL := 10

MANIFEST := datasets_manifest/datasets.yaml
DATASETS := alaska andes-aconcagua andes-chile appalachians gobi highlands \
            himalaya-annapurna himalaya-everest karakoram norway pyrenees rockies sahara
REPORTS := reports
STAMPS := .cache/stamps
DATA_STAMP := $(STAMPS)/data-verified

# stage: per-dataset DEM summary (summary.md is written last, after hillshade.png and summary.json)
SUMMARY_SRC := orokit/io/dem.py orokit/io/fetch.py orokit/reports/dem_summary.py orokit/cli/report_dataset.py
DATASET_SUMMARIES := $(DATASETS:%=$(REPORTS)/datasets/%/summary.md)

# stage: classification (issue 6). Reads the analysis folders reports/analysis/<name>/.
ANALYSIS_JSONS := $(DATASETS:%=$(REPORTS)/analysis/%/analysis.json)
CLASSIFY_SRC := $(wildcard orokit/classify/*.py orokit/sampling/*.py orokit/metrics/disk.py) \
                orokit/reports/classification.py orokit/reports/classification_calibration.py orokit/cli/report.py \
                orokit/io/model_io.py
CLASSIFICATION_README := $(REPORTS)/classification/README.md
CLASSIFICATION_PAPER_README := $(REPORTS)/classification/paper/README.md

ANALYSIS_README := $(REPORTS)/analysis/README.md
REPORT_OUTPUTS := $(DATASET_SUMMARIES) $(REPORTS)/README.md $(ANALYSIS_README) $(CLASSIFICATION_README) \
                  $(CLASSIFICATION_PAPER_README)

# stage: Divide Tree synthesis (issue 7): a terrain type per region (from its analysis), a
# 90 x 90 km synthesized tree per type (seed 0), and the fidelity table reports/synthesis/README.md.
SYNTH_SRC := $(wildcard orokit/synthesis/*.py) orokit/cli/type_cmd.py orokit/cli/synthesize_tree.py
SYNTH_TYPES := $(DATASETS:%=$(REPORTS)/synthesis/types/%.json)
SYNTH_TREES := $(DATASETS:%=$(REPORTS)/synthesis/trees/%/synthesis.json)
SYNTHESIS_README := $(REPORTS)/synthesis/README.md
REPORT_OUTPUTS += $(SYNTH_TYPES) $(SYNTHESIS_README)

.PHONY: report test data venv clean-reports help analysis classification region-model synthesis generators

.DEFAULT_GOAL := report

help:  ## list targets
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | sed 's/:.*## /\t/'

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(INSTALLED): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install -e '.[dev]'
	touch $@

venv: $(INSTALLED)  ## create .venv and install orokit[dev]

test: $(INSTALLED)  ## type-check orokit (mypy, cache in .mypy_cache), then run the test suite on 2 cores
	$(BIN)/python -m mypy
	$(BIN)/python -m pytest -q --doctest-modules orokit
	$(BIN)/python -m pytest -n 2 tests $(PYTEST_ARGS)

$(DATA_STAMP): $(MANIFEST) | $(INSTALLED)
	@mkdir -p $(@D)
	$(OROKIT) data fetch
	$(OROKIT) data verify
	touch $@

data: $(DATA_STAMP)  ## fetch and verify every dataset of the manifest

$(REPORTS)/datasets/%/summary.md: $(DATA_STAMP) $(SUMMARY_SRC) | $(INSTALLED)
	$(OROKIT) -q report-dataset $* -o $(@D) --overwrite

# stage: exact analysis (issues 4, 5) of each manifest DEM at eps = 30 m (units and cell size from
# the manifest); analysis.json is written last.
ANALYSIS_SRC := orokit/analysis.py $(wildcard orokit/topology/*.py orokit/tiling/*.py) orokit/metrics/_kernels.py \
                orokit/metrics/isolation.py orokit/io/dem.py orokit/io/analysis_io.py orokit/cli/analyze.py
$(REPORTS)/analysis/%/analysis.json: $(DATA_STAMP) $(ANALYSIS_SRC) | $(INSTALLED)
	$(OROKIT) -q analyze $* -o $(@D) --min-prominence 30 --overwrite --no-progress

$(ANALYSIS_README): $(ANALYSIS_JSONS) orokit/reports/analysis_report.py orokit/validate/reference.py | $(INSTALLED)
	$(OROKIT) -q analysis-report $(ANALYSIS_JSONS:%/analysis.json=%) -o $@ --overwrite

analysis: $(ANALYSIS_README)  ## exact analysis of every DEM, table + Divide Tree figures

# the region model (terrain features, R = 10 km, seed 0): a build product, not tracked (.gitignore). Built
# alone from the analyses: the report's disks, the spatial hold-out its calibration comes from (30 runs),
# the forest; the same trees and calibration as the report's model, without the report's other runs
REGION_MODEL := models/regions-10km.skops
REGION_MODEL_ARGS := --radius 10km --features terrain --classifier et --runs 30
$(REGION_MODEL): $(ANALYSIS_JSONS) $(CLASSIFY_SRC) | $(INSTALLED)
	$(OROKIT) -q report $(ANALYSIS_JSONS:%/analysis.json=%) --model-only --model $@ -o .cache/region-model \
	  $(REGION_MODEL_ARGS) --overwrite --no-progress

region-model: $(REGION_MODEL)  ## the region model alone (models/regions-10km.skops, ~3 min): orokit classify, the round trip, benchmarks/realism.py

$(CLASSIFICATION_README): $(ANALYSIS_JSONS) $(CLASSIFY_SRC) | $(INSTALLED)
	$(OROKIT) -q report $(ANALYSIS_JSONS:%/analysis.json=%) -o $(REPORTS)/classification $(REGION_MODEL_ARGS) \
	  --feature-runs 5 --block-runs 3 --open-set-runs 3 --overwrite

# the paper's protocol and feature set (reference mode), kept beside the default figures
$(CLASSIFICATION_PAPER_README): $(ANALYSIS_JSONS) $(CLASSIFY_SRC) | $(INSTALLED)
	$(OROKIT) -q report $(ANALYSIS_JSONS:%/analysis.json=%) -o $(@D) --radius 10km --features paper \
	  --classifier rf --runs 30 --feature-runs 5 --overwrite --no-progress

classification: $(CLASSIFICATION_README) $(CLASSIFICATION_PAPER_README) $(REGION_MODEL)  ## region classification reports (default and paper protocol), models/regions-10km.skops

$(REPORTS)/synthesis/types/%.json: $(REPORTS)/analysis/%/analysis.json $(SYNTH_SRC) | $(INSTALLED)
	$(OROKIT) -q type $(<D) -o $@ --name $* --overwrite

# synthesis.json is the last of the four files synthesize-tree writes
$(REPORTS)/synthesis/trees/%/synthesis.json: $(REPORTS)/synthesis/types/%.json $(SYNTH_SRC) | $(INSTALLED)
	$(OROKIT) -q synthesize-tree --type $< --size 90km --seed 0 -o $(@D) --overwrite --no-progress

$(SYNTHESIS_README): $(SYNTH_TREES) orokit/cli/synthesis_report.py | $(INSTALLED)
	$(OROKIT) -q synthesis-report $(SYNTH_TREES:%/synthesis.json=%) -o $@ --overwrite

synthesis: $(SYNTHESIS_README)  ## terrain types per region, synthesized 90 km trees, fidelity table

# stage: round trip (issue 8). For every region: a synthetic twin of the real DEM (same size and
# cell size, tree + eroded raster from the region's type, seed 0), its re-analysis and classification
# by the region model (validation.json), then the table + side-by-side hillshades (README.md).
ROUNDTRIP_SRC := $(wildcard orokit/raster/*.py orokit/validate/*.py) orokit/cli/synthesize.py orokit/cli/render.py
ROUNDTRIP_MODEL := $(REGION_MODEL)
ROUNDTRIP_VALIDATIONS := $(DATASETS:%=$(REPORTS)/roundtrip/%/validation.json)
ROUNDTRIP_README := $(REPORTS)/roundtrip/README.md
REPORT_OUTPUTS += $(ROUNDTRIP_README)

# hillshade.png is the last of the files synthesize writes
$(REPORTS)/roundtrip/%/hillshade.png: $(REPORTS)/synthesis/types/%.json $(DATA_STAMP) $(SYNTH_SRC) $(ROUNDTRIP_SRC) | $(INSTALLED)
	$(OROKIT) -q synthesize --type $< --like $* --seed 0 -o $(@D) --overwrite

$(REPORTS)/roundtrip/%/validation.json: $(REPORTS)/roundtrip/%/hillshade.png $(REGION_MODEL) orokit/cli/validate.py | $(INSTALLED)
	$(OROKIT) -q validate $(@D) --model $(ROUNDTRIP_MODEL) --overwrite

# the render of each region's own (real) Divide Tree on the real DEM's grid, defaults (issue 11)
ROUNDTRIP_RENDERS := $(DATASETS:%=$(REPORTS)/roundtrip/render/%.tif)
$(REPORTS)/roundtrip/render/%.tif: $(REPORTS)/analysis/%/analysis.json $(ROUNDTRIP_SRC) | $(INSTALLED)
	$(OROKIT) -q render $(<D)/dividetree.gpkg --like $* --seed 0 -o $@ --overwrite

$(ROUNDTRIP_README): $(ROUNDTRIP_VALIDATIONS) $(ROUNDTRIP_RENDERS) $(CLASSIFICATION_README) orokit/reports/roundtrip.py orokit/reports/landform.py orokit/cli/roundtrip_report.py | $(INSTALLED)
	$(OROKIT) -q roundtrip-report $(ROUNDTRIP_VALIDATIONS:%/validation.json=%) --model $(ROUNDTRIP_MODEL) \
	  --renders $(REPORTS)/roundtrip/render \
	  --classification $(REPORTS)/classification/tables/per_class_10km.csv -o $@ --overwrite --no-progress

# the same twins with the real DEM's elevation as the coarse elevation control C_H (paper section 5):
# the large-scale relief follows the real one, every peak, saddle, ridge and detail is synthesized
RELIEF_VALIDATIONS := $(DATASETS:%=$(REPORTS)/roundtrip/relief/%/validation.json)
RELIEF_README := $(REPORTS)/roundtrip/relief/README.md
REPORT_OUTPUTS += $(RELIEF_README)

$(REPORTS)/roundtrip/relief/%/hillshade.png: $(REPORTS)/synthesis/types/%.json $(DATA_STAMP) $(SYNTH_SRC) $(ROUNDTRIP_SRC) | $(INSTALLED)
	$(OROKIT) -q synthesize --type $< --like $* --control-elevation like --seed 0 -o $(@D) --overwrite

$(REPORTS)/roundtrip/relief/%/validation.json: $(REPORTS)/roundtrip/relief/%/hillshade.png $(REGION_MODEL) orokit/cli/validate.py | $(INSTALLED)
	$(OROKIT) -q validate $(@D) --model $(ROUNDTRIP_MODEL) --overwrite

$(RELIEF_README): $(RELIEF_VALIDATIONS) $(CLASSIFICATION_README) orokit/reports/roundtrip.py orokit/cli/roundtrip_report.py | $(INSTALLED)
	$(OROKIT) -q roundtrip-report $(RELIEF_VALIDATIONS:%/validation.json=%) --model $(ROUNDTRIP_MODEL) \
	  --classification $(REPORTS)/classification/tables/per_class_10km.csv -o $@ --overwrite --no-progress

roundtrip: $(ROUNDTRIP_README) $(RELIEF_README)  ## synthetic twins of every region (free, and with the real relief as C_H)

# stage: generator ranking (issues 17-20). Per region and seed one synthesized Divide Tree of the real
# DEM's size (648 x 92.61 m, the shape of the four DEMs), rendered by every generator in its own process
# on the DEM's grid, then re-analysed, reclassified and compared with the real landforms (result.json);
# the table, README.csv and side-by-side hillshades in reports/generators/.
GEN_REGIONS := sahara appalachians karakoram norway
GEN_SEEDS := 0 1 2
GEN_NAMES := argudo belhadj rusnell michel guerin
# guerin-cross: Guérin with another region's DEM as exemplar (real texture may flatter reclassification)
GEN_CROSS_sahara := appalachians
GEN_CROSS_appalachians := karakoram
GEN_CROSS_karakoram := norway
GEN_CROSS_norway := sahara
GEN_SIZE := 60011.28m
GEN_RUNDIR := $(REPORTS)/generators/runs
GEN_SRC := $(wildcard orokit/generators/*.py) orokit/cli/generators_cmd.py orokit/cli/generator_options.py \
           orokit/cli/render.py $(wildcard orokit/raster/*.py) orokit/validate/roundtrip.py orokit/validate/landform.py
GEN_RESULTS := $(foreach r,$(GEN_REGIONS),$(foreach s,$(GEN_SEEDS),$(foreach g,$(GEN_NAMES) guerin-cross,$(GEN_RUNDIR)/$(r)/seed$(s)/$(g)/result.json)))
GEN_README := $(REPORTS)/generators/README.md
REPORT_OUTPUTS += $(GEN_README)

define GEN_TREE_RULE
$(GEN_RUNDIR)/$(1)/seed$(2)/tree/synthesis.json: $(REPORTS)/synthesis/types/$(1).json $(SYNTH_SRC) | $(INSTALLED)
	$(OROKIT) -q synthesize-tree --type $$< --size $(GEN_SIZE) --seed $(2) -o $$(@D) --overwrite --no-progress
endef
define GEN_RUN_RULE
$(GEN_RUNDIR)/$(1)/seed$(2)/$(3)/result.json: $(GEN_RUNDIR)/$(1)/seed$(2)/tree/synthesis.json $(DATA_STAMP) $(REGION_MODEL) $(GEN_SRC) | $(INSTALLED)
	$(OROKIT) -q generators-run --tree $$(<D) --type $(REPORTS)/synthesis/types/$(1).json --like $(1) \
	  --generator $(3) --seed $(2) --model $(REGION_MODEL) -o $$@ --overwrite
endef
define GEN_CROSS_RULE
$(GEN_RUNDIR)/$(1)/seed$(2)/guerin-cross/result.json: $(GEN_RUNDIR)/$(1)/seed$(2)/tree/synthesis.json $(DATA_STAMP) $(REGION_MODEL) $(GEN_SRC) | $(INSTALLED)
	$(OROKIT) -q generators-run --tree $$(<D) --type $(REPORTS)/synthesis/types/$(1).json --like $(1) \
	  --generator guerin --exemplar $(GEN_CROSS_$(1)) --label guerin-cross --seed $(2) --model $(REGION_MODEL) -o $$@ --overwrite
endef
$(foreach r,$(GEN_REGIONS),$(foreach s,$(GEN_SEEDS),$(eval $(call GEN_TREE_RULE,$(r),$(s)))))
$(foreach r,$(GEN_REGIONS),$(foreach s,$(GEN_SEEDS),$(eval $(call GEN_CROSS_RULE,$(r),$(s)))))
$(foreach r,$(GEN_REGIONS),$(foreach s,$(GEN_SEEDS),$(foreach g,$(GEN_NAMES),$(eval $(call GEN_RUN_RULE,$(r),$(s),$(g))))))

$(GEN_README): $(GEN_RESULTS) orokit/reports/generators.py orokit/cli/generators_cmd.py | $(INSTALLED)
	$(OROKIT) -q generators-report $(GEN_RESULTS) -o $@ --overwrite

generators: $(GEN_README)  ## generator ranking table (argudo, belhadj, ...) in reports/generators/

# the index links every section that exists (reports/*/README.md, benchmarks): built after all stages.
# Keep these two rules last, so that every stage above has appended its outputs (prerequisites expand
# when a rule is read).
INDEX_SRC := orokit/cli/report_index.py orokit/reports/index.py orokit/reports/dem_summary.py
$(REPORTS)/README.md: $(DATASET_SUMMARIES) $(filter-out $(REPORTS)/README.md,$(REPORT_OUTPUTS)) $(INDEX_SRC) | $(INSTALLED)
	$(OROKIT) -q report-index $(patsubst %/summary.md,%/summary.json,$(DATASET_SUMMARIES)) -o $@ --overwrite

report: $(REPORT_OUTPUTS)  ## main pipeline: data, summaries, analysis, classification, synthesis, round trip, generator ranking

clean-reports:  ## delete generated reports (keeps data and .venv)
	rm -rf $(REPORTS)/datasets $(REPORTS)/README.md
