"""Drafting a marker-set profile from a recording's labels, by the common naming conventions.

Each label is split into a side (L/R: a token "L", "Left", "Lt", a leading letter glued to a known name as in
Plug-in Gait's "LKNE", a trailing "_L", or the side in a front/back token such as "FL") and a name; the name is
looked up in ``NAMES``: the words the common conventions use for each landmark (Plug-in Gait and the CMU/Vicon
sets, ISB/Qualisys abbreviations, OpenSim's and other descriptive English names, the MoCap Toolbox set). A
landmark with several candidates takes the one listed first. Where a convention puts two markers around a
landmark (front and back of the head, the two posterior iliac spines, two metatarsals) the draft takes their mean.
Every line of the draft says which label it guessed from and why, for the user to check.
"""
from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass

# landmark stem -> names (token tuples, most specific first); sided unless the stem is a midline landmark
NAMES: dict[str, tuple[tuple[str, ...], ...]] = {
    "SACR": (("SACR",), ("SACRUM",), ("SACRAL",), ("SACRO",), ("V", "SACRAL"), ("WAIST", "BACK")),
    "IAS": (("IAS",), ("ASIS",), ("ASI",), ("EIAS",), ("FWT",), ("HIP", "F"), ("WAIST", "FRONT")),
    "IPS": (("IPS",), ("PSIS",), ("PSI",), ("EIPS",), ("BWT",), ("HIP", "B"), ("WAIST", "BACK")),
    "TV12": (("TV12",), ("T12",), ("TH12",), ("T10",), ("TV10",), ("T8",), ("TV8",), ("SPINE",), ("MID", "BACK"),
             ("MIDBACK",), ("BBAC",), ("SPINE", "THORACIC12")),
    "TV2": (("TV2",), ("T2",), ("C7",), ("CV7",), ("SPINE", "THORACIC2"), ("BACK", "TOP"), ("SPINE", "TOP")),
    "SME": (("SME",), ("CLAV",), ("SNJ",), ("SJN",), ("JN",), ("STRN",), ("STERNUM",), ("STER",), ("MAN",),
            ("MANUBRIUM",), ("CHEST",), ("SXS",), ("XYPH",), ("XIPHOID",)),
    "SGL": (("SGL",), ("GLAB",), ("FOREHEAD",), ("HEAD", "FRONT")),
    "HDF": (("FHD",), ("HDF",), ("HEAD", "F"), ("HEAD", "FRONT")),
    "HDB": (("BHD",), ("HDB",), ("HEAD", "B"), ("HEAD", "BACK")),
    "HEAD": (("HEAD",),),
    "SHF": (("FSH",), ("SHOULDER", "F"), ("SHOULDER", "FRONT")),
    "SHB": (("BSH",), ("SHOULDER", "B"), ("SHOULDER", "BACK")),
    "SAE": (("SAE",), ("SHO",), ("SHOULDER",), ("ACR",), ("ACROMION",), ("ACROMIUM",), ("AC",), ("SAJ",),
            ("SHOULDER", "TOP")),
    "HLE": (("HLE",), ("ELB",), ("ELBOW", "LAT"), ("EPI", "LAT"), ("ELBL",), ("LEL",), ("LEE",), ("ELBOW", "OUT"),
            ("ELBOW",)),
    "HME": (("HME",), ("ELBOW", "MED"), ("EPI", "MED"), ("ELBM",), ("MEL",), ("IEL",), ("MELB",), ("MEE",),
            ("ELBOW", "IN")),
    "UOA": (("UOA",), ("OLEC",), ("OLECRANON",)),
    "RSP": (("RSP",), ("WRA",), ("WRIST", "RAD"), ("WRR",), ("OWR",), ("RADIUS",), ("RAD",), ("WRIST", "LAT"),
            ("LW",), ("WRIST", "OUT"), ("WRIST",), ("WRI",), ("WRS",)),
    "USP": (("USP",), ("WRB",), ("WRIST", "ULN"), ("WRU",), ("IWR",), ("UHE",), ("ULNA",), ("ULN",), ("WRIST", "MED"),
            ("MW",), ("WRIST", "IN")),
    "HM2": (("HM2",), ("FIN",), ("MCP2",), ("FINGER",), ("HAND",), ("IHAND",), ("HAND", "IN"), ("HAND", "OUT")),
    "PAS": (("PAS",), ("PAT",), ("PATELLA",)),
    "FLE": (("FLE",), ("KNE",), ("KNEE", "LAT"), ("KNEL",), ("LKNE",), ("LKE",), ("LEK",), ("KNEE", "OUT"), ("KNEE",)),
    "FME": (("FME",), ("KNEE", "MED"), ("KNM",), ("KNEM",), ("KNI",), ("MKNE",), ("MKE",), ("MEK",), ("KNEE", "IN")),
    "TTC": (("TTC",), ("TTA",), ("TT",), ("TIBTUB",)),
    "FAL": (("FAL",), ("ANK",), ("ANKLE", "LAT"), ("LMAL",), ("ANKL",), ("LM",), ("ANKLE", "OUT"), ("ANKLE",)),
    "TAM": (("TAM",), ("ANKLE", "MED"), ("MMAL",), ("ANKM",), ("MED", "MAL"), ("MANK",), ("MM",), ("ANKLE", "IN")),
    "FCC": (("FCC",), ("HEE",), ("HEEL",), ("HEL",), ("CALC",), ("CALCA",), ("CAL",), ("HEEL", "BACK")),
    "FM2": (("FM2",), ("TOE",), ("MT2",), ("TOE2",), ("TOE", "TIP")),
    "FM1": (("FM1",), ("MT1",), ("BIG", "TOE"), ("BIGTOE",), ("FOOT", "MED"), ("1META",), ("P1MT",), ("TOE", "IN"),
            ("FOREFOOT", "IN")),
    "FM5": (("FM5",), ("MT5",), ("PINKIE",), ("FOOT", "LAT"), ("5META",), ("P5MT",), ("TOE", "OUT"),
            ("FOREFOOT", "OUT")),
}
MIDLINE = {"SACR", "TV12", "TV2", "SME", "SGL"}
# Landmarks a convention marks with a pair of markers around them, found as their mean ("{s}": each side in turn):
# (landmark, (stem, side) of each marker, what they are)
PAIR_MEANS = (("SACR", ("IPS", "L"), ("IPS", "R"), "the two posterior iliac spines"),
              ("SGL", ("HDF", "L"), ("HDF", "R"), "the two front head markers"),
              ("{s}_HEAD", ("HDF", "{s}"), ("HDB", "{s}"), "the front and back head markers on that side"),
              ("{s}_SAE", ("SHF", "{s}"), ("SHB", "{s}"), "the front and back shoulder markers on that side"),
              ("{s}_FM2", ("FM1", "{s}"), ("FM5", "{s}"), "the 1st and 5th metatarsal markers"))
_SIDE_WORDS = {"L": "L", "LEFT": "L", "LT": "L", "R": "R", "RIGHT": "R", "RT": "R"}
_ALL_NAMES = {n for names in NAMES.values() for name in names for n in name}


@dataclass
class Label:
    label: str
    side: str | None
    name: tuple[str, ...]


def parse(label: str, prefix: str = "") -> Label:
    """'male:LKNE' -> (L, KNE); 'R.Knee.Lat' -> (R, KNEE LAT); 'Hip_FL' -> (L, HIP F); 'L_HEAD' -> (L, HEAD);
    ``prefix``: what every label starts with, not read ('S01_LKNE' -> (L, KNE))."""
    text = label.rsplit(":", 1)[-1].strip()[len(prefix):]
    text = re.sub(r"(?<=[a-z])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", " ", text)  # camelCase -> words ("WaistLFront")
    tokens = [t.upper() for t in re.split(r"[^A-Za-z0-9]+", text) if t]
    side = None
    rest = []
    for t in tokens:
        if side is None and t in _SIDE_WORDS:
            side = _SIDE_WORDS[t]
        elif side is None and len(t) == 2 and t[0] in "FB" and t[1] in "LR":   # front/back + side: "FL"
            side = t[1]
            rest.append(t[0])
        else:
            rest.append(t)
    if side is None and rest and rest[0][0] in "LR" and len(rest[0]) > 1 and rest[0][1:] in _ALL_NAMES:
        side, rest[0] = rest[0][0], rest[0][1:]                # Plug-in Gait: "LKNE" -> L + KNE
    return Label(label, side, tuple(rest))


def _find(labels: list[Label], stem: str, side: str | None) -> tuple[str, tuple[str, ...]] | None:
    for name in NAMES[stem]:
        for lab in labels:
            if lab.name == name and (lab.side == side or (side is None and lab.side is None)):
                return lab.label.rsplit(":", 1)[-1].strip(), name
    return None


def draft(labels: list[str]) -> tuple[dict[str, str], dict[str, str], list[str]]:
    """(landmark -> expression, landmark -> why, landmarks not found). Labels that all start alike (a subject's
    initial or number: 'S01_LKNE', 'JLKNE') are also read without that prefix, and the reading that finds more
    landmarks is kept (a set of one side's markers starts alike too: 'LASI', 'LKNE')."""
    bases = [x.rsplit(":", 1)[-1].strip() for x in labels]
    common = os.path.commonprefix(bases) if len(bases) > 1 else ""
    readings = [_draft([parse(x) for x in labels])]
    if common and len(common) < min(map(len, bases)):
        readings.append(_draft([parse(x, common) for x in labels]))
    return max(readings, key=lambda r: len(r[0]))


def _draft(parsed: list[Label]) -> tuple[dict[str, str], dict[str, str], list[str]]:
    from mocap_core.profiles import LANDMARKS

    got: dict[str, str] = {}
    why: dict[str, str] = {}

    def one(stem, side):
        found = _find(parsed, stem, side)
        return found[0] if found else None

    for landmark in LANDMARKS:
        side, stem = (landmark[0], landmark[2:]) if landmark[:2] in ("L_", "R_") else (None, landmark)
        hit = _find(parsed, stem, side)
        if hit:
            got[landmark], why[landmark] = hit[0], f"{hit[0]}: named {' '.join(hit[1]).lower()}"
    for target, (stem_a, side_a), (stem_b, side_b), what in PAIR_MEANS:
        for side in ("L", "R") if "{s}" in target else ("",):
            landmark = target.format(s=side)
            a, b = one(stem_a, side_a.format(s=side)), one(stem_b, side_b.format(s=side))
            if landmark not in got and a and b:
                got[landmark], why[landmark] = f"mean({a}, {b})", f"the mean of {what}"
    # one ulna marker beside a radius marker is the wrist's, else it is the elbow's point
    for side in "LR":
        if got.get(f"{side}_USP") and re.fullmatch(r"(?i).*ulna", got[f"{side}_USP"]) and f"{side}_RSP" not in got:
            got[f"{side}_UOA"] = got.pop(f"{side}_USP")
            why[f"{side}_UOA"] = why.pop(f"{side}_USP") + " (no radius marker beside it: the elbow's point)"
    missing = [x for x in LANDMARKS if x not in got]
    return {x: got[x] for x in LANDMARKS if x in got}, why, missing


def draft_yaml(name: str, labels: list[str], up_axis: str, source: str) -> str:
    """The draft profile as YAML, every guess commented."""
    from mocap_core.landmark_needs import site

    got, why, missing = draft(labels)
    used = {m for expr in got.values() for m in re.findall(r"[^\s(),]+", expr) if m != "mean"}
    lines = [f"# Drafted by `mocap profile init` from {source}: check every line against your marker placement.",
             f"name: {json.dumps(name)}", f"description: {json.dumps(f'drafted from {source}')}",
             f"up_axis: {up_axis}              # the vertical axis of files that do not say it",
             "strip_prefixes: true", "landmarks:" if got else "landmarks: {}   # none guessed: fill them in"]
    for landmark, expr in got.items():
        lines.append(f"  {landmark + ':':8s}{expr:28s} # {site(landmark)}; guessed from {why[landmark]}")
    if missing:
        lines.append("# Not found (add them if your set has them; `mocap profile explain` says what each locates):")
        lines += [f"#  {landmark}: ?   ({site(landmark)})" for landmark in missing]
    unused = [x for x in labels if x.rsplit(":", 1)[-1] not in used]
    if unused:
        lines.append("# Labels not used: " + ", ".join(unused))
    return "\n".join(lines) + "\n"
