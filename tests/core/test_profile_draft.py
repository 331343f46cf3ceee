"""Drafting a profile from the labels of marker-set conventions we do not ship: the takes of ../shared/data with
their labels renamed by the published tables of OpenSim's, OptiTrack Motive's and Qualisys's conventions, or in lower
case as some databases store them, with and without a subject prefix."""
import pytest

from tests.conftest import data_file

# OpenSim's gait and full-body models (Gait2392, the full-body running model): "R.Knee.Lat", "R.Acromium", ...
OPENSIM = {"FWT": "{s}.ASIS", "BWT": "{s}.PSIS", "KNE": "{s}.Knee.Lat", "ANK": "{s}.Ankle.Lat", "HEE": "{s}.Heel",
           "TOE": "{s}.Toe.Tip", "SHO": "{s}.Acromium", "ELB": "{s}.Elbow", "WRA": "{s}.Wrist.Lat",
           "WRB": "{s}.Wrist.Med", "FIN": "{s}.Finger", "FHD": "{s}.Head.Front", "BHD": "{s}.Head.Back",
           "MT5": "{s}.MT5", "THI": "{s}.Thigh.Front", "SHN": "{s}.Shank.Front", "UPA": "{s}.Bicep",
           "FRM": "{s}.Forearm", "BAC": "{s}.Back", "STRN": "Sternum", "CLAV": "Clavicle",
           "FSH": "{s}.Shoulder.Front", "BSH": "{s}.Shoulder.Back", "KNI": "{s}.Knee.Med", "IEL": "{s}.Elbow.Med"}
# The 47-marker Human Body Model of OpenSim's full-body work (AddBiomechanics): "RLKE", "RLEE", "RLW", "RMW", ...
HUMAN_BODY = {"FWT": "{s}ASIS", "BWT": "{s}PSIS", "KNE": "{s}LKE", "KNI": "{s}MKE", "ANK": "{s}LM", "ELB": "{s}LEE",
              "IEL": "{s}MEE", "WRA": "{s}LW", "WRB": "{s}MW", "OWR": "{s}LW", "IWR": "{s}MW", "FHD": "{s}HEAD",
              "THI": "F{s}THI", "SHN": "{s}ATI", "UPA": "{s}DELT"}
# OptiTrack Motive's baseline set ("WaistLFront", "LKneeOut", "LWristIn", ...; head markers kept as they are)
MOTIVE = {"FWT": "Waist{s}Front", "BWT": "Waist{s}Back", "KNE": "{s}KneeOut", "KNI": "{s}KneeIn", "ANK": "{s}AnkleOut",
          "HEE": "{s}Heel", "HEL": "{s}HeelBack", "TOE": "{s}ToeTip", "MT1": "{s}ToeIn", "MT5": "{s}ToeOut",
          "SHO": "{s}ShoulderTop", "ELB": "{s}ElbowOut", "IEL": "{s}ElbowIn", "WRA": "{s}WristOut", "WRB": "{s}WristIn",
          "OWR": "{s}WristOut", "IWR": "{s}WristIn", "FIN": "{s}HandOut", "IHAND": "{s}HandIn", "OHAND": "{s}HandOut",
          "THI": "{s}Thigh", "SHN": "{s}Shin", "UPA": "{s}UArmHigh", "STRN": "Chest", "C7": "BackTop", "T10": "T10",
          "FSH": "{s}ShoulderFront", "BSH": "{s}ShoulderBack"}
# Qualisys's animation set ("Q_WaistLFront", "Q_SpineThoracic12", "Q_LShoulderTop", ...)
QUALISYS_ANIMATION = {**MOTIVE, "C7": "SpineThoracic2", "T10": "SpineThoracic12", "FHD": "Head{s}Front",
                      "BHD": "Head{s}Back"}
TAKES = ["08_cmu_135_02_karate_kata.c3d", "12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"]


def renamed(label: str, table: dict[str, str] | None, prefix: str) -> str:
    """``label`` by ``table`` (None: the same names in lower case) after ``prefix``."""
    base = label.rsplit(":", 1)[-1]
    if table is None:
        base = base.lower()
    elif base in table:
        base = table[base].format(s="")
    elif base[0] in "LR" and base[1:] in table:
        base = table[base[1:]].format(s=base[0])
    return prefix + base


@pytest.mark.parametrize("take", TAKES)
@pytest.mark.parametrize("convention", ["opensim", "human_body", "motive", "qualisys_animation", "lowercase"])
@pytest.mark.parametrize("prefix", ["", "S01_", "J"])
def test_a_draft_locates_what_the_shipped_profile_does(take, convention, prefix):
    """At least 90 % of the joint-frames the shipped profile locates, from the draft of the renamed labels."""
    from mocap_core.localization import Localizer
    from mocap_core.profile_draft import draft
    from mocap_core.profiles import Profile, detect_profile
    from mocap_core.recordings import read_recording

    rec = read_recording(data_file(take))
    table = {"opensim": OPENSIM, "human_body": HUMAN_BODY, "motive": MOTIVE,
             "qualisys_animation": QUALISYS_ANIMATION, "lowercase": None}[convention]
    prefix = "Q_" + prefix if convention == "qualisys_animation" else prefix
    labels = [renamed(x, table, prefix) for x in rec.labels]
    landmarks, _, _ = draft(labels)
    positions = rec.positions[:600].astype(float)
    located = {}
    for name, profile, names in (("draft", Profile(name="draft", landmarks=landmarks), labels),
                                 ("shipped", detect_profile(rec.labels), rec.labels)):
        lm = profile.resolve(names).apply(positions)
        located[name] = int((Localizer(profile.body).localize(lm).status != 0).sum())
    assert located["draft"] >= 0.9 * located["shipped"], (located, landmarks)


def test_one_sides_markers_keep_their_side():
    # every label starts with "L" here, but that "L" is the side, not a subject's prefix
    from mocap_core.profile_draft import draft

    landmarks, _, _ = draft(["LASI", "LKNE", "LANK", "LHEE", "LTOE"])
    assert landmarks == {"L_IAS": "LASI", "L_FLE": "LKNE", "L_FAL": "LANK", "L_FCC": "LHEE", "L_FM2": "LTOE"}
