# The two commands of the README. Each sets itself up: a virtual environment in .venv with the
# project installed (editable) and its test dependencies.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test setup bench clean bvh-blender golden results results-blend results-beyond results-short targets checks results-rigid results-options

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

setup: $(STAMP)

demo: $(STAMP)
	$(BIN)/mocap demo

# The viewer test drives a real headless Chromium (Debian's package; root or sudo installs it).
CHROMIUM_STAMP := $(VENV)/.chromium
$(CHROMIUM_STAMP):
	command -v chromium >/dev/null 2>&1 || { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; }
	touch $(CHROMIUM_STAMP)

test: $(STAMP) $(CHROMIUM_STAMP)
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/python benchmarks/transport.py

# A BVH of the karate take imported by Blender headless (Debian's blender; not run by CI): prints the frame count
# and each limb's rest direction, so a T-pose shows as arms "lateral" and legs "down".
bvh-blender: $(STAMP)
	command -v blender >/dev/null 2>&1 || { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq blender; }
	$(BIN)/mocap solve ../shared/data/08_cmu_135_02_karate_kata.c3d --profile cmu41 --bvh-out /tmp/mocap-karate.bvh \
		--bvh-names mixamo --quiet
	blender -b --factory-startup --python scripts/blender_bvh_check.py -- /tmp/mocap-karate.bvh 2>&1 | grep -v "^Blender\|^Read\|^$$"

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis

# The golden bag of the regression test (tests/nodes/test_bags.py): the first 240 frames of a real
# take with real gaps, replayed in lockstep through launch/studio.yaml, skeleton/solved recorded.
# Re-make it only when a change of results is intended, and say so in the commit.
GOLDEN_TAKE := ../shared/data/12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d
golden: $(STAMP)
	rm -f tests/data/golden_solved*.mcap  # a recorder writes a new piece beside a file that exists
	$(BIN)/mocap bag from-recording $(GOLDEN_TAKE) --frames 240 -o /tmp/mocap-golden-raw.mcap
	$(BIN)/mocap bag play /tmp/mocap-golden-raw.mcap --launch launch/studio.yaml --lockstep --restamp \
		--record tests/data/golden_solved.mcap --set viewer.port=0 --set retarget.max_wait_ms=5000

# docs/results.md: thesis Tables 4.1-4.3 and Figures 4.5-4.6/4.10 reproduced on ../shared/data.
results: $(STAMP)
	$(BIN)/mocap eval timing --report docs/results/timing
	$(BIN)/mocap eval gaps --remove elbow_l --from 1 --report docs/results/elbow_sprint
	$(BIN)/mocap eval gaps --take ../shared/data/13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat:dance1 \
		--profile dance28 --remove knee_l,ankle_l --from 5 --to 15 --report docs/results/knee_ankle_dance

results-blend: $(STAMP)
	$(BIN)/mocap eval gaps --take ../shared/data/13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat:dance1 \
		--profile dance28 --remove knee_l,ankle_l --from 5 --to 15 --solvers ccd --constraints on --mode markers \
		--reacquire-step 0.01 --report docs/results/knee_ankle_dance_blend

# The gap-filling options beyond the thesis that the studio graphs use (gapfill.BEYOND_THESIS), as flags of
# `mocap eval gaps`, with constraints on and the markers removed; a run adds its landmark fills
# (--rebuild, --pose-memory).
GAPS_OPTIONS := --constraints on --mode markers --pair-guard --swivel --segment-carry --limb-memory --body-model \
	--reacquire-step 0.01
GAPS_BEYOND_NO_BLEND := $(GAPS_OPTIONS) --end-model
GAPS_BEYOND := $(GAPS_BEYOND_NO_BLEND) --blend-half-life 0.1
GAPS_BEYOND_NO_END := $(GAPS_OPTIONS) --blend-half-life 0.1

# A whole limb lost (elbow, wrist and hand; knee, ankle, foot and toe) 1 s in every 2 s, three ways: the thesis's
# method, the studio options without the end model, and with it. $(1): take, profile, limb, window; $(2): report
# name; $(3): the landmark fills.
define whole_limb
	$(BIN)/mocap eval gaps --gap-length 1 --gap-every 2 --solvers ccd $(1) --constraints on --mode markers --no-plots \
		--report docs/results/limb_$(2)_thesis
	$(BIN)/mocap eval gaps --gap-length 1 --gap-every 2 --solvers ccd $(1) $(GAPS_BEYOND_NO_END) $(3) --no-plots \
		--report docs/results/limb_$(2)_no_end_model
	$(BIN)/mocap eval gaps --gap-length 1 --gap-every 2 --solvers ccd $(1) $(GAPS_BEYOND) $(3) --report docs/results/limb_$(2)_studio
endef

results-beyond: $(STAMP)
	$(BIN)/mocap eval timing --constraints on --beyond --report docs/results/timing_beyond
	$(call whole_limb,--remove elbow_l$(,)wrist_l$(,)hand_l --from 1,arm_sprint,--rebuild)
	$(call whole_limb,--take ../shared/data/08_cmu_135_02_karate_kata.c3d --profile cmu41 --remove elbow_l$(,)wrist_l$(,)hand_l --from 1 --to 20,arm_karate,--rebuild)
	$(call whole_limb,--take $(DANCE):walk2 --profile dance28 --remove elbow_l$(,)wrist_l$(,)hand_l --from 1,arm_walk2,)
	$(call whole_limb,--take $(DANCE):dance2 --profile dance28 --remove elbow_r$(,)wrist_r$(,)hand_r --from 1,arm_dance2,)
	$(call whole_limb,--take $(DANCE):walk1 --profile dance28 --remove knee_l$(,)ankle_l$(,)foot_l$(,)toe_l --from 1,leg_walk1,--pose-memory)
	$(BIN)/mocap eval gaps --take ../shared/data/13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat:dance1 \
		--profile dance28 --remove knee_l,ankle_l --from 5 --to 15 $(GAPS_BEYOND) --report docs/results/knee_ankle_dance_beyond
	$(BIN)/mocap eval gaps --take ../shared/data/02_qualisys_walking_ezc3d_Qualisys.c3d --profile qualisys_sports \
		--remove knee_l,ankle_l --from 0.5 --to 2.0 $(GAPS_BEYOND) --report docs/results/knee_ankle_walk_beyond
	$(BIN)/mocap eval gaps --remove elbow_l --from 1 $(GAPS_BEYOND) --rebuild --report docs/results/elbow_sprint_rebuild
	$(BIN)/mocap eval gaps --take ../shared/data/02_qualisys_walking_ezc3d_Qualisys.c3d --profile qualisys_sports \
		--remove foot_l --from 0.5 --to 1.5 $(GAPS_BEYOND) --rebuild --report docs/results/heel_walk_rebuild
	$(BIN)/mocap eval gaps --remove L_USP --from 1 $(GAPS_BEYOND) --rebuild --report docs/results/styloid_sprint_rebuild
	$(BIN)/mocap eval gaps --take ../shared/data/12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d \
		--profile vicon53 --remove R_USP --from 1 $(GAPS_BEYOND) --rebuild --report docs/results/styloid_vicon_rebuild_r
	$(BIN)/mocap eval gaps --take ../shared/data/02_qualisys_walking_ezc3d_Qualisys.c3d --profile qualisys_sports \
		--remove pelvis --from 0.5 --to 2.0 --solvers ccd --constraints on --mode markers --hips-lost fit \
		--report docs/results/pelvis_walk_fit
	$(BIN)/mocap eval gaps --take ../shared/data/02_qualisys_walking_ezc3d_Qualisys.c3d --profile qualisys_sports \
		--remove knee_l,ankle_l --from 0.5 --to 2.0 $(GAPS_BEYOND) --rebuild --report docs/results/knee_ankle_walk_rebuild
	$(BIN)/mocap eval gaps --remove knee_l,ankle_l --from 1 --to 2.5 $(GAPS_BEYOND) --rebuild --report docs/results/knee_ankle_sprint_rebuild
	$(BIN)/mocap eval gaps --take ../shared/data/02_qualisys_walking_ezc3d_Qualisys.c3d --profile qualisys_sports \
		--remove elbow_l --from 0.3 $(GAPS_BEYOND) --rebuild --report docs/results/elbow_walk_rebuild
	$(BIN)/mocap eval gaps --take ../shared/data/08_cmu_135_02_karate_kata.c3d --profile cmu41 \
		--remove elbow_l --from 1 --to 20 $(GAPS_BEYOND) --rebuild --report docs/results/elbow_karate_rebuild
	$(BIN)/mocap eval gaps --take ../shared/data/08_cmu_135_02_karate_kata.c3d --profile cmu41 \
		--remove elbow_r --from 1 --to 20 $(GAPS_BEYOND) --rebuild --report docs/results/elbow_karate_rebuild_r
	$(BIN)/mocap eval gaps --take $(DANCE):dance1 --profile dance28 --remove shoulder_l --from 1 $(GAPS_BEYOND) --rebuild \
		--report docs/results/shoulder_dance1_rebuild
	$(BIN)/mocap eval gaps --take ../shared/data/08_cmu_135_02_karate_kata.c3d --profile cmu41 \
		--remove shoulder_l --from 1 --to 20 $(GAPS_BEYOND) --rebuild --report docs/results/shoulder_karate_rebuild
	$(BIN)/mocap eval gaps --take ../shared/data/13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat:dance1 \
		--profile dance28 --remove knee_l,ankle_l --from 5 --to 15 $(GAPS_BEYOND) --pose-memory --report docs/results/knee_ankle_dance_memory
	$(BIN)/mocap eval gaps --take ../shared/data/13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat:walk1 \
		--profile dance28 --remove knee_l,ankle_l --from 2 $(GAPS_BEYOND) --pose-memory --report docs/results/knee_ankle_walk1_memory
	$(BIN)/mocap eval gaps --take ../shared/data/08_cmu_135_02_karate_kata.c3d --profile cmu41 \
		--remove knee_l,ankle_l --from 1 --to 20 $(GAPS_BEYOND) --rebuild \
		--report docs/results/knee_ankle_karate_rebuild
	for side in l r; do \
		$(BIN)/mocap eval gaps --take ../shared/data/12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d \
			--profile vicon53 --remove elbow_$$side --from 1 $(GAPS_BEYOND) --rebuild \
			--report docs/results/elbow_vicon_rebuild_$$side \
			|| exit 1; \
		$(BIN)/mocap eval gaps --take ../shared/data/12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d \
			--profile vicon53 --remove knee_$$side,ankle_$$side --from 1 $(GAPS_BEYOND) --rebuild \
			--report docs/results/knee_ankle_vicon_rebuild_$$side || exit 1; done
	for take in dance1 dance2 walk1 walk2; do for side in l r; do \
		$(BIN)/mocap eval gaps --take ../shared/data/13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat:$$take \
			--profile dance28 --remove elbow_$$side --from 1 --solvers ccd $(GAPS_BEYOND) \
			--report docs/results/elbow_swivel_$${take}_$$side \
			|| exit 1; done; done
	# the pose memory on every leg of the 28-marker set (the dances 5-15 s, the walks from 2 s): the targets' table
	for take in dance1 dance2 walk1 walk2; do for side in l r; do \
		case $$take in dance*) window="--from 5 --to 15";; *) window="--from 2";; esac; \
		$(BIN)/mocap eval gaps --take ../shared/data/13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat:$$take \
			--profile dance28 --remove knee_$$side,ankle_$$side $$window --solvers ccd $(GAPS_BEYOND) --pose-memory \
			--no-plots --report docs/results/knee_ankle_memory_$${take}_$$side \
			|| exit 1; done; done

# The gap-filling targets, met or not, read from the reports that results, results-beyond and results-short write
# (runs nothing itself).
targets: $(STAMP)
	$(BIN)/mocap eval targets --report docs/results/targets

# What each recording's markers do wrong (gaps, markers of one bone off their spacing), before anything is solved.
checks: $(STAMP)
	$(BIN)/mocap check ../shared/data/02_qualisys_walking_ezc3d_Qualisys.c3d --profile qualisys_sports \
		--report docs/results/take_check/qualisys_walk
	$(BIN)/mocap check ../shared/data/03_sprint_start_BTK_SprintMotion.trc --profile btk_sprint \
		--report docs/results/take_check/sprint
	$(BIN)/mocap check ../shared/data/08_cmu_135_02_karate_kata.c3d --profile cmu41 --report docs/results/take_check/karate
	$(BIN)/mocap check ../shared/data/12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d --profile vicon53 \
		--report docs/results/take_check/vicon
	for take in dance1 dance2 walk1 walk2; do \
		$(BIN)/mocap check $(DANCE):$$take --profile dance28 --report docs/results/take_check/$$take || exit 1; done

# Short gaps, as a studio's occlusions are (91 % of the Vicon take's real gaps last 0.1 s or less): the joints
# hidden 0.1 s in every 0.5 s, each case three ways: the thesis's method, the studio graphs' options without the
# blend at loss, and with it. $(1): take, profile, joints, window; $(2): report name; $(3): the landmark fills
# ($(,) is a comma inside a call's argument).
, := ,
SHORT_GAPS := --gap-length 0.1 --gap-every 0.5 --solvers ccd
DANCE := ../shared/data/13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat
define short_gaps
	$(BIN)/mocap eval gaps $(SHORT_GAPS) $(1) --constraints on --mode markers --no-plots \
		--report docs/results/short_$(2)_thesis
	$(BIN)/mocap eval gaps $(SHORT_GAPS) $(1) $(GAPS_BEYOND_NO_BLEND) $(3) --no-plots --report docs/results/short_$(2)_studio
	$(BIN)/mocap eval gaps $(SHORT_GAPS) $(1) $(GAPS_BEYOND) $(3) --report docs/results/short_$(2)_blend
endef

results-short: $(STAMP)
	$(call short_gaps,--remove elbow_l --from 1,elbow_sprint,--rebuild)
	$(call short_gaps,--take ../shared/data/08_cmu_135_02_karate_kata.c3d --profile cmu41 --remove elbow_l --from 1 --to 20,elbow_karate,--rebuild)
	$(call short_gaps,--take ../shared/data/02_qualisys_walking_ezc3d_Qualisys.c3d --profile qualisys_sports --remove knee_l$(,)ankle_l --from 0.3 --gap-every 0.3,knee_ankle_walk,--rebuild)
	$(call short_gaps,--take ../shared/data/12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d --profile vicon53 --remove elbow_r --from 1,elbow_vicon,--rebuild)
	$(call short_gaps,--take ../shared/data/12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d --profile vicon53 --remove knee_r$(,)ankle_r --from 1,knee_ankle_vicon,--rebuild)
	$(call short_gaps,--take $(DANCE):dance2 --profile dance28 --remove knee_l$(,)ankle_l --from 1,knee_ankle_dance2,--pose-memory)
	$(call short_gaps,--take $(DANCE):dance1 --profile dance28 --remove knee_l$(,)ankle_l --from 1,knee_ankle_dance1,--pose-memory)
	for take in dance1 dance2 walk1 walk2; do for side in l r; do \
		$(BIN)/mocap eval gaps $(SHORT_GAPS) --take $(DANCE):$$take --profile dance28 --remove elbow_$$side --from 1 \
			--constraints on --mode markers --no-plots --report docs/results/short_elbow_$${take}_$${side}_thesis || exit 1; \
		$(BIN)/mocap eval gaps $(SHORT_GAPS) --take $(DANCE):$$take --profile dance28 --remove elbow_$$side --from 1 \
			$(GAPS_BEYOND_NO_BLEND) --no-plots --report docs/results/short_elbow_$${take}_$${side}_studio || exit 1; \
		$(BIN)/mocap eval gaps $(SHORT_GAPS) --take $(DANCE):$$take --profile dance28 --remove elbow_$$side --from 1 \
			$(GAPS_BEYOND) --report docs/results/short_elbow_$${take}_$${side}_blend || exit 1; done; done
	$(BIN)/mocap eval real-gaps --report docs/results/real_gaps_vicon


# The thesis's method, the studio options and the rigid-skeleton fit side by side on every take (docs/fit.md).
results-rigid: $(STAMP)
	$(BIN)/mocap eval rigid --report docs/results/rigid

# What each studio option adds: each left out in turn, on every take.
results-options: $(STAMP)
	$(BIN)/mocap eval options --report docs/results/options
