"""Rebuilding lost limb landmarks from the markers of their segment that are still seen.

Beyond the thesis (the "use what is still visible: a joint's remaining markers"; the thesis's
2018 code had a first version of it, SegmentTracking, facts section 8). The markers of one bone
move as one rigid body, so a lost landmark is put where the best rigid motion (Kabsch) of its
segment's seen markers, from the last frame they were seen with it, carries it:

- forearm: the humeral epicondyles sit on the elbow's flexion axis, which the ulna turns about, so
  they keep their place among the forearm's markers (olecranon, both styloids; the styloids are
  partners only);
- foot: the malleoli sit on the ankle's hinge, so they keep their place among heel and toe;
- shank: the femoral epicondyles sit on the knee's flexion axis, which the tibia turns about, so they
  (and the tibial tuberosity) keep their place among the malleoli (partners only) and the shank's
  tracking markers;
- thorax: the acromion keeps its place among the trunk's markers (the other acromion, the spine's, the
  sternum's), as near as the shoulder blade lets it;
- styloids: one lost while the other is seen keeps its place among the other and the forearm's markers.

A profile's ``tracking`` markers (wands and clusters that no landmark names, e.g. the Qualisys set's
forearm and shank wands) join their bone as partners: the sets without an olecranon marker can then
rebuild an elbow too. The upper arm's tracking markers then pull a rebuilt elbow epicondyle to its
learned distances from them (``ALSO_ON``).

A landmark is rebuilt only from at least ``MIN_PARTNERS`` markers of its segment seen both now and
in its reference frame: two leave the rotation about their line free (the forearm's swivel, which
the IK stage's swivel option handles). Two do when they run along the bone, a tracking marker on its
shaft and a landmark at its end (``MIN_SHAFT_PARTNERS``): the roll about the bone is then all that
is left, and it is kept from the reference. Partners on one line, or two across the bone, do for a
member the bone above holds (``ALSO_ON``) when that bone's tracking markers are seen: they fix the roll
about the line. Tried and left out, because they made the fills worse on the
recordings: the malleoli rebuilt from the shank (a lost ankle came out 45 mm off where the foot's
carry gives 4 mm) and the hand with the forearm (a wrist flexes).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
from numba import njit

from mocap_core.fill_units import LandmarkFill, MarkerSet, switch
from mocap_core.ik.kernels import (angle_about, axis_angle, best_roll, follow, line_carry, mv, nearness_weight,
                                   rigid_fit_weighted, vfinite, vnorm)
from mocap_core.profiles import LANDMARK_INDEX, LANDMARKS, TRACKING_BONES

MIN_PARTNERS = 3
# Two partners leave the rotation about their line free. When one is a tracking marker on the bone's
# shaft (a wand, a forearm or shank marker) and the other a landmark at its end, their line runs along
# the bone, and a lost landmark is carried by the least rotation that turns that line (its roll about
# the bone kept from the reference). A knee with only the ankle and one shank marker left is then carried
# with its shank instead of left to IK. Two landmarks (the wrist's styloids, say) run across the bone: left to the IK stage's swivel, unless the bone
# above fixes the roll (ROLL_PRICE, below).
MIN_SHAFT_PARTNERS = 2
# Partners nearly on one line leave the rotation about it free (a toe marker between two metatarsal
# markers, say): they must spread at least this far (RMS) from their best line. (An elbow marker
# with two wrist markers 6 cm apart spreads 7-9 mm: enough.)
MIN_SPREAD_M = 0.005
# In the rigid fit each partner weighs by its nearness to the member in the reference (kernels.nearness_weight):
# skin slides less near the point than far along the bone, so near partners say more of where it went.
REBUILD_HELP = ("beyond the thesis: a lost elbow, olecranon, knee, ankle, heel or toe marker rebuilt from the rigid "
                "motion of at least 3 markers of its forearm, shank or foot still seen (with the profile's tracking "
                "markers; of the styloids or malleoli, one that slid on the skin left out; a forearm's roll also "
                "from the upper arm's, as far as they fix it), or of 2 along the bone (a"
                " tracking marker and a landmark; a forearm's rolled by the upper arm's), or of markers on one line "
                "rolled by the bone above's; elbow, knee and ankle held to the upper arm's, thigh's and shank's "
                "markers; then a lost knee and ankle from the hip and one shank marker, or the ankle (the leg hinge),"
                " which also turns a knee rebuilt from 2 to keep its distances from the hip; a lost styloid, while the "
                "other is seen, from it and at least 3 more of the forearm's markers; a lost acromion carried "
                "with the trunk's markers; and a landmark that is the mean of several markers, still lost, kept while"
                " some are seen (a lost one keeps its offset, turned as the markers nearest it turn)")
# Rigid bodies of landmarks: (bone, rebuilt when lost, partners only), in the order they are rebuilt:
# the shank's partners include the malleoli the foot may have rebuilt just before. The profile's
# tracking markers of a bone (wands, clusters) join it as partners. The styloids help the forearm, but are not
# rebuilt from the elbow's markers: the radius turns about the ulna, which those do not see, and the IK stage's
# swivel does better; one is rebuilt only while the other is seen (below). The malleoli are never rebuilt from the
# shank, whose markers do not see the ankle's flexion; the foot's do.
# A name is a landmark of the segment's side ("HLE": L_HLE on the left), of the other side ("other SAE"), or one
# of the trunk's ("TV2").
SEGMENTS = (
    ("forearm", ("HLE", "HME", "UOA"), ("RSP", "USP")),  # the elbow's axis, the olecranon, the styloids
    ("foot", ("FAL", "TAM", "FCC", "FM2"), ()),          # the ankle's axis (malleoli), heel and toe
    ("shank", ("FLE", "FME", "TTC"), ("FAL", "TAM")),    # the knee's axis, the tibia, the ankle's axis
    ("thorax", ("SAE",), ("other SAE", "TV2", "TV12", "SME")),  # the acromion with the trunk (below)
    ("styloids", ("RSP", "USP"), ("HLE", "HME", "UOA")),  # one styloid, while the other is seen (below)
)
# One styloid lost and the other seen: the wrist joint, the styloids' mean, is lost with it, and IK can only guess
# it; the forearm's other markers and the other styloid put it far nearer (its tracking markers too: FAR_END_OF
# names the bone whose they are). Only with at least LONE_PARTNERS["styloids"] of those others seen besides the
# other styloid: a wrist bar turns with pronation about the forearm's line, which one elbow and one forearm marker
# do not see. Both lost, the wrist is left to the IK stage (above).
FAR_END_OF = {"styloids": "forearm"}
LONE_PARTNERS = {"styloids": 3}  # a pair each rebuilt only while the other is seen: how many more partners it needs
# The acromion rides the shoulder blade, which slides on the ribs, but far less than a lost one's stand-ins move:
# the chest would fall back to other markers (and jump) and the shoulder joint to the arm's IK. So a lost acromion
# is carried rigidly with the trunk (the other acromion, both spine markers and the sternum).
# A joint's landmarks belong to the bone above as well: once their own bone's motion has put them, they
# are moved to keep their learned distances to that bone's tracking markers (bone lengths are constant,
# and skin slides: a fit's rotation errors grow away from its markers). Per bone: the members refined, the bone
# above, and whether the bone's own tracking markers hold their distances firmly too (second pass, below).
# The malleoli keep theirs to the shank's markers, not to the foot's, whose distances change as the foot
# flexes; the knee's epicondyles keep theirs to a thigh marker, not to the shank's.
ALSO_ON = {"forearm": (("HLE", "HME"), "upper_arm", True),
           "foot": (("FAL", "TAM"), "shank", False),
           "shank": (("FLE", "FME"), "thigh", False)}
assert set(ALSO_ON) | {above for _, above, _ in ALSO_ON.values()} <= set(TRACKING_BONES)
DISTANCE_RATE = 1 / 100  # how fast a learned distance follows the frames where both points are measured
DISTANCE_PRIOR = 0.1     # weight of the rigid estimate against the distances (per squared metre)
# Then a second pass keeps the distances to the tracking markers alone, firmly (the estimate's weight
# TRACKING_PRIOR): wands and clusters ride the bone's flesh and keep their distances to an epicondyle within a
# few millimetres, where the styloids, on a turning radius under sliding skin, do not. The first pass leaves the
# point where all of them agree best; the second moves it towards the distances that hold.
TRACKING_PRIOR = 0.3
EVERY_POINT = np.int64(-1)  # _keep_distances' held_from for the first pass (a numpy int: see n in rebuild_frame)
# Partners on one line, or two across the bone, leave the rotation about their line free: the roll. Where the bone
# above is seen, a refined member is carried by the least turn of that line and then rolled about it to the angle
# that keeps its learned distances to the bone above's tracking markers best (searched within MAX_ROLL either
# side, in ROLL_STEP steps, then tenths and hundredths; ROLL_PRICE, square metres per square radian, holds it
# near the reference's roll where they hardly fix it, as in the leg hinge's roll). A foot with the heel lost keeps
# only its metatarsals, on one line; the shank's markers then fix the ankle.
MAX_ROLL = np.radians(90.0)
ROLL_STEP = np.radians(5.0)
ROLL_PRICE = 0.001
# A forearm rolls about its shaft (pronation: up to 150 deg), a shank hardly does. So where two partners along
# the forearm are left (its marker and the outer wrist marker), the roll kept from the reference frame may be
# long gone: the member is rolled by the upper arm's markers instead, and of the two rolls one distance leaves
# (mirror images) the search keeps to the one nearest the member's point in the frame before (without it, a fast
# swing picks the wrong mirror). Rolling the shank so made the knees worse.
ROLLS_ABOUT_SHAFT = ("forearm",)
# Where three or more partners are left, the rigid fit carries the forearm's roll from its wrist markers. But skin
# and a wrist bar turn with pronation, the ulna and the epicondyles do not: the lateral epicondyle's marker keeps
# its distances to the forearm's and the upper arm's markers within millimetres, to the wrist markers only within
# centimetres. So a forearm's member is also rolled about the forearm's line (the styloids' mean to its tracking
# markers' mean) to keep its distances to the upper arm's markers, as a member with two partners is. That roll is
# only as firm as those distances change with it: taken in full where they change by ROLL_FIRM_FULL (metres per
# radian) or more, not where by ROLL_FIRM_FROM or less (with the arm held straight the upper arm's marker lies
# nearly along the forearm's line as seen from the elbow), blended in between with the fit kept to its distances.
ROLL_FIRM_FROM = 0.02
ROLL_FIRM_FULL = 0.08
# Two partners whose spacing bone fixes: the styloids sit on the ends of the radius and the ulna, which the distal
# radio-ulnar joint holds together (pronation turns them together), the malleoli on the tibia and the fibula. When
# their spacing has changed by over SLID_M since the member's reference, one of them has slid on the skin (or was
# put off by the cameras), and the one whose distances to the segment's other seen partners changed more is left
# out of the fit. While that cannot be told (the other partners lost, or the pair not both seen) the last verdict
# stands. (A wrist marker can slide centimetres up the forearm while the pair's spacing changes by millimetres.)
BONY_PAIRS = {"forearm": ("RSP", "USP"), "shank": ("FAL", "TAM")}
SLID_M = 0.005
# A marker can also slide with the pair's spacing kept. So while one of the pair has its distances to the segment's
# other seen partners changed by over SLID_ALONG_M, and by over SLID_ALONG_RATIO times the other's, it is found slid
# once that has held for SLID_ALONG_S, spacing or not. A strike swings a forearm's skin against its wrist bar for
# less than that, and those markers are not left out.
SLID_ALONG_M = 0.02
SLID_ALONG_RATIO = 3.0
SLID_ALONG_S = 0.25
N_LANDMARKS = len(LANDMARKS)


def segment_landmark(side: str, name: str) -> str:
    """A name of SEGMENTS as a landmark on one side: "HLE" -> "L_HLE", "other SAE" -> "R_SAE", "TV2" -> "TV2"."""
    if name in LANDMARK_INDEX:  # the trunk's
        return name
    if name.startswith("other "):
        return f"{'R' if side == 'L' else 'L'}_{name.removeprefix('other ')}"
    return f"{side}_{name}"


def tracking_segment(side: str, bone: str) -> str:
    """The profile's tracking segment whose markers move with a bone of SEGMENTS ("L_forearm" for the styloids)."""
    return f"{side}_{FAR_END_OF.get(bone, bone)}"


def segment_table(tracking_of: Sequence[str] = ()
                  ) -> tuple[np.ndarray, ...]:
    """Point indices per segment (segments x width; the rebuilt members first, then the partners and the
    bone's tracking markers, then the points used for distances only; -1 padding), and per segment how
    many are rebuilt, how many move rigidly with it, how many of the first are refined by distances, from
    which point on the tracking markers hold those distances firmly (0: the bone's own too), whether it
    rolls about its shaft (ROLLS_ABOUT_SHAFT), where in its row its bony pair is (BONY_PAIRS; -1: none), and,
    for a pair each rebuilt only while the other is seen, how many other partners that needs (0: not one;
    LONE_PARTNERS).
    Points are the landmarks, then the tracking markers (``tracking_of``: the segment of each, e.g.
    "L_forearm")."""
    def tracks(name):
        return [len(LANDMARKS) + j for j, seg in enumerate(tracking_of) if seg == name]

    rows, counts, pairs = [], [], []
    for side in ("L", "R"):
        for bone, rebuilt, partners in SEGMENTS:
            own = tracks(tracking_segment(side, bone))
            rigid = [LANDMARK_INDEX[segment_landmark(side, name)] for name in rebuilt + partners] + own
            refined, above, own_too = ALSO_ON.get(bone, ((), "", False))
            distance_only = tracks(f"{side}_{above}") if above else []
            assert rebuilt[:len(refined)] == refined  # the refined ones lead the rebuilt ones
            rows.append(rigid + distance_only)
            assert bone not in LONE_PARTNERS or len(rebuilt) == 2  # (a pair: each rebuilt while the other is seen)
            counts.append((len(rebuilt), len(rigid), len(refined) if distance_only else 0,
                           0 if own_too else len(rigid), bone in ROLLS_ABOUT_SHAFT,
                           LONE_PARTNERS.get(bone, 0)))
            pair = BONY_PAIRS.get(bone)
            pairs.append([(rebuilt + partners).index(name) for name in pair] if pair else [-1, -1])
    width = max(map(len, rows))
    table = np.array([r + [-1] * (width - len(r)) for r in rows], np.int64)
    rebuilt_count, rigid_count, refined_count, held_from, shaft_rolls, lone = (np.array(c, np.int64)
                                                                               for c in zip(*counts))
    return table, rebuilt_count, rigid_count, refined_count, held_from, shaft_rolls, np.array(pairs, np.int64), lone


class SegmentRebuilder(LandmarkFill):
    """Fills lost limb landmarks frame by frame. Keep one per actor: it owns the reference frames.
    ``tracking_of``: the segment of each tracking marker passed to :meth:`fill` (LandmarkMap.tracking_of)."""
    Settings = switch("rebuild", REBUILD_HELP)

    @classmethod
    def for_marker_set(cls, markers: MarkerSet) -> "SegmentRebuilder":
        return cls(markers.tracking_of)

    def __init__(self, tracking_of: Sequence[str] = ()):
        (self.segments, self.rebuilt_count, self.rigid_count, self.refined_count,
         self.held_from, self.shaft_rolls, self.pairs, self.lone) = segment_table(tracking_of)
        self.n_tracking = len(tracking_of)
        width = self.segments.shape[1]
        # per segment and member: where the segment's markers were the last time that member was
        # seen with at least MIN_PARTNERS of the others (NaN rows: not seen then)
        self.reference = np.full((len(self.segments), width, width, 3), np.nan)
        # per segment, refined member and point: their learned distance (NaN: never measured together)
        self.distance = np.full((len(self.segments), width, width), np.nan)
        # per segment and member: its point in the frame before, seen or rebuilt (NaN: neither)
        self.last = np.full((len(self.segments), width, 3), np.nan)
        # per segment and member: which of the bony pair was last found slid against its reference (-1: neither)
        self.slid = np.full((len(self.segments), width), -1, np.int64)
        # per segment and member: which of the pair has slid along with the spacing kept (SLID_ALONG_M; -1:
        # neither), and since when (seconds)
        self.along = np.full((len(self.segments), width), -1, np.int64)
        self.along_since = np.full((len(self.segments), width), np.nan)
        # (as the kernel takes them)
        self._table = (self.segments, self.rebuilt_count, self.rigid_count, self.refined_count, self.held_from,
                       self.shaft_rolls, self.pairs, self.lone)
        self._state = (self.reference, self.distance, self.last, self.slid, self.along, self.along_since)

    def fill(self, landmarks, tracking=None, time_s=np.nan, markers=None, filled=None) -> np.ndarray:
        """One frame (LandmarkFill.fill): fill what can be rebuilt, in place. ``tracking``: as many as
        ``tracking_of`` said; ``time_s`` NaN: a marker slid with its pair's spacing kept is not found
        (SLID_ALONG_S)."""
        points = landmarks
        if self.n_tracking:
            if tracking is None or len(tracking) != self.n_tracking:
                raise ValueError(f"expected {self.n_tracking} tracking markers, got "
                                 f"{'none' if tracking is None else len(tracking)}")
            points = np.concatenate([landmarks, tracking])
        rebuilt = np.zeros(len(points), np.bool_)
        rebuild_frame(points, self._table, self._state, float(time_s), rebuilt)
        if points is not landmarks:
            landmarks[:] = points[:len(landmarks)]
        return rebuilt[:len(landmarks)]


@njit(cache=True)
def rebuild_frame(lm, table, state, time_s, rebuilt):
    """One frame, in place (SegmentRebuilder.fill): ``table``, the segments (segment_table: segments,
    rebuilt_count, rigid_count, refined_count, held_from, shaft_rolls, pairs, lone); ``state``, what the rebuild
    keeps (reference, distance, last, slid, along, along_since); ``rebuilt``: the points put. Plain tuples: numba
    reads them from Python faster than NamedTuples."""
    width = table[0].shape[1]
    # work arrays: which members are seen; a member's gathered partners before and after, their weights and which
    # are tracking markers; the bone above's points; each member in the frame before
    work = (np.zeros(width, np.bool_), np.empty((width, 3)), np.empty((width, 3)), np.empty(width),
            np.zeros(width, np.bool_), np.empty((1, 3)), np.empty((width, 3)), np.empty((width, 3)))
    for s in range(table[0].shape[0]):
        _rebuild_segment(s, lm, table, state, time_s, rebuilt, work)


@njit(cache=True, inline="always")
def _rebuild_segment(s, lm, table, state, time_s, rebuilt, work):
    segments, rebuilt_count, rigid_count, refined_count, _, _, pairs, lone = table
    reference, distance, last, slid, along, along_since = state
    seen, previous = work[0], work[7]
    seg, rigid = segments[s], rigid_count[s]
    width, count = np.int64(0), 0  # int64 from the start: a literal would compile each kernel it reaches twice
    for k in range(seg.shape[0]):
        if seg[k] < 0:
            break
        width += 1
        seen[k] = vfinite(lm[seg[k]])
        if seen[k] and k < rigid:
            count += 1
        if k < rebuilt_count[s]:
            previous[k] = last[s, k]
            last[s, k] = lm[seg[k]]  # (NaN when lost; a rebuilt one is written below)
    _learn_distances(lm, seg, width, refined_count[s], seen, rebuilt, distance[s])
    # Each seen member's reference: the segment as it is now, unless that has fewer partners than
    # the one kept, which then stays (a heel lost a frame before its ankle would leave a reference of the
    # metatarsals alone, all on one line, from which the ankle cannot be rebuilt).
    if count > MIN_SHAFT_PARTNERS:
        for k in range(rigid):
            if seen[k] and count - 1 >= _partners(reference[s, k], k, rigid):
                slid[s, k], along[s, k] = -1, -1
                for m in range(rigid):
                    if seen[m]:
                        reference[s, k, m] = lm[seg[m]]
                    else:
                        reference[s, k, m] = np.nan
    if count == rigid or count < MIN_SHAFT_PARTNERS:
        return
    segment = (lm, seg, rigid, width, seen)
    for k in range(rebuilt_count[s]):
        if seen[k] or rebuilt[seg[k]] or not vfinite(reference[s, k, k]):
            continue
        if lone[s] and not (seen[1 - k] and not rebuilt[seg[1 - k]]):  # (a lone styloid: the other one seen)
            continue
        slid[s, k] = _slid(segment, reference[s, k], (pairs[s, 0], pairs[s, 1]), slid[s, k],
                           (along[s], along_since[s]), k, time_s)
        _rebuild_member(s, k, segment, table, state, rebuilt, work)


@njit(cache=True, inline="always")
def _rebuild_member(s, k, segment, table, state, rebuilt, work):
    """Member k of segment s, lost: from the rigid motion of its partners seen, or carried along a line of two
    and rolled by the bone above; then held to its learned distances."""
    lm, seg, rigid, width, seen = segment
    refined_count, held_from, shaft_rolls, lone = table[3], table[4], table[5], table[7]
    reference, distance, last, slid = state[0], state[1], state[2], state[3]
    _, before, after, weights, on_shaft, point, above, previous = work
    n, shaft = np.int64(0), 0  # int64 from the start: a literal would compile each kernel it reaches twice
    for m in range(rigid):
        if m != slid[s, k] and seen[m] and vfinite(reference[s, k, m]):
            before[n], after[n] = reference[s, k, m], lm[seg[m]]
            weights[n] = nearness_weight(vnorm(reference[s, k, m] - reference[s, k, k]))
            on_shaft[n] = seg[m] >= N_LANDMARKS
            if on_shaft[n]:
                shaft += 1
            n += 1
    # (rolled: carried by partners i and j's line, then about it by the bone above; forearm_roll: from the
    # member's side of that line in the frame before, see ROLLS_ABOUT_SHAFT)
    if lone[s] and n - 1 < lone[s]:
        return
    rolled, forearm_roll, fitted_roll, i, j = False, False, False, 0, 1
    if n >= MIN_PARTNERS and _spread(before, n) >= MIN_SPREAD_M:
        rot, t = rigid_fit_weighted(before, after, weights, n)
        fitted_roll = (shaft_rolls[s] == 1 and k < refined_count[s] and 0 < shaft < n
                       and _above_seen(rigid, width, seen, distance[s, k]))
    elif n == MIN_SHAFT_PARTNERS and shaft == 1:
        rot, t = line_carry(before[0], before[1], after[0], after[1])
        forearm_roll = shaft_rolls[s] == 1 and k < refined_count[s] and _above_seen(rigid, width, seen,
                                                                                      distance[s, k])
        rolled = forearm_roll
    elif n >= 2 and k < refined_count[s] and _above_seen(rigid, width, seen, distance[s, k]):
        i, j = _farthest(before, n)
        rot, t = line_carry(before[i], before[j], after[i], after[j])
        rolled = True
    else:
        return
    p = mv(rot, reference[s, k, k]) + t
    if forearm_roll and vfinite(previous[k]):
        p = _turned_toward(p, after[i], after[j], previous[k])
    if rolled:
        p = _roll_by_above(p, (after[i], after[j]), segment, distance[s, k], (point, above))
    elif k < refined_count[s]:
        p = _held_to_distances(p, segment, distance[s, k], held_from[s], (after, on_shaft, n, fitted_roll),
                               (point, above))
    lm[seg[k]] = p
    last[s, k] = p
    rebuilt[seg[k]] = True


@njit(cache=True)
def _held_to_distances(p, segment, distance, held_from, partners, work):
    """A refined member's rigid estimate ``p`` held to its learned distances (DISTANCE_PRIOR, TRACKING_PRIOR),
    and, as firmly as the bone above fixes it, rolled about the shaft's line by that bone's tracking markers
    (``partners``: the gathered (after, on_shaft, n, fitted_roll); ROLL_FIRM_FROM)."""
    after, on_shaft, n, fitted_roll = partners
    firm, rolled_p = 0.0, p
    if fitted_roll:  # (ROLL_FIRM_FROM)
        line = _shaft_line(after, on_shaft, n)
        firm = _roll_firmness(p, line, segment, distance)
        if firm > 0.0:
            rolled_p = _roll_by_above(p, line, segment, distance, work)
    kept = rolled_p
    if firm < 1.0:
        kept = _keep_distances(p, segment, distance, DISTANCE_PRIOR, EVERY_POINT)
        kept = _keep_distances(kept, segment, distance, TRACKING_PRIOR, held_from)
    return firm * rolled_p + (1.0 - firm) * kept


@njit(cache=True)
def _slid(segment, reference, pair, before, sliding_since, k, time_s):
    """Which of the bony pair at positions ``pair`` = (i, j) (i -1: none) has slid since ``reference``, the
    member's (BONY_PAIRS): -1 while their spacing holds, unless one has slid along with it kept for SLID_ALONG_S
    (``sliding_since`` = (along, along_since): the segment's, kept here; ``k``: the member); ``before`` (the last
    verdict) where it cannot be told. ``segment``: this frame's (lm, seg, rigid, width, seen)."""
    lm, seg, rigid, _, seen = segment
    i, j = pair
    along, along_since = sliding_since
    if i < 0 or not (vfinite(reference[i]) and vfinite(reference[j])):
        return -1
    if not (seen[i] and seen[j]):
        return before
    moved_i, moved_j, others = 0.0, 0.0, 0
    for m in range(rigid):
        if m != i and m != j and seen[m] and vfinite(reference[m]):
            moved_i = max(moved_i, _stretch(lm, seg, reference, i, m))
            moved_j = max(moved_j, _stretch(lm, seg, reference, j, m))
            others += 1
    sliding = -1
    if others and max(moved_i, moved_j) > max(SLID_ALONG_M, SLID_ALONG_RATIO * min(moved_i, moved_j)):
        sliding = i if moved_i > moved_j else j
    if sliding != along[k] or time_s < along_since[k]:  # (a stream restarted, its clock with it: start over)
        along[k], along_since[k] = sliding, time_s
    if _stretch(lm, seg, reference, i, j) <= SLID_M:
        return sliding if sliding >= 0 and time_s - along_since[k] >= SLID_ALONG_S else -1
    if others == 0:
        return before
    return i if moved_i > moved_j else j


@njit(cache=True)
def _stretch(lm, seg, reference, a, b):
    """How far the distance between points a and b of a segment's row has changed since ``reference``."""
    return abs(vnorm(lm[seg[a]] - lm[seg[b]]) - vnorm(reference[a] - reference[b]))


@njit(cache=True)
def _turned_toward(p, pivot, toward, target):
    """``p`` turned about the line from ``pivot`` toward ``toward`` to the side of it where ``target`` is."""
    line = (toward - pivot) / max(vnorm(toward - pivot), 1e-9)
    return pivot + mv(axis_angle(line, angle_about(line, p - pivot, target - pivot)), p - pivot)


@njit(cache=True)
def _roll_by_above(p, line, segment, distance, work):
    """``p`` turned about the ``line`` (pivot, toward) to keep its learned distances to the bone above's seen
    tracking markers best (``work``: the arrays point and above)."""
    pivot, toward = line
    lm, seg, rigid, width, seen = segment
    point, above = work
    line = (toward - pivot) / max(vnorm(toward - pivot), 1e-9)
    point[0] = p
    for m in range(rigid, width):
        above[m - rigid] = np.nan
        if seen[m]:
            above[m - rigid] = lm[seg[m]]
    angle = best_roll(pivot, line, point, above[:width - rigid], distance[rigid:width].reshape(1, width - rigid),
                      ROLL_PRICE, MAX_ROLL, ROLL_STEP)
    return pivot + mv(axis_angle(line, angle), p - pivot)


@njit(cache=True)
def _shaft_line(partners, on_shaft, n):
    """The forearm's line among the first n of a member's gathered partners: from the mean of the landmarks (the
    styloids) to the mean of the tracking markers (``on_shaft``)."""
    ends, counts = np.zeros((2, 3)), np.zeros(2)
    for m in range(n):
        end = 1 if on_shaft[m] else 0
        ends[end] += partners[m]
        counts[end] += 1
    return ends[0] / counts[0], ends[1] / counts[1]


@njit(cache=True)
def _roll_firmness(p, line, segment, distance):
    """How far to trust a roll of ``p`` about the ``line`` (pivot, toward) by the bone above's tracking markers
    (0-1): by how fast its distance to them changes with the roll, metres per radian, at best (ROLL_FIRM_FROM,
    ROLL_FIRM_FULL)."""
    pivot, toward = line
    lm, seg, rigid, width, seen = segment
    line = (toward - pivot) / max(vnorm(toward - pivot), 1e-9)
    across = np.cross(line, p - pivot)  # p's velocity per radian of roll
    rate = 0.0
    for m in range(rigid, width):
        if seen[m] and not np.isnan(distance[m]):
            u = p - lm[seg[m]]
            rate = max(rate, abs((across * u).sum()) / max(vnorm(u), 1e-9))
    return min(1.0, max(0.0, (rate - ROLL_FIRM_FROM) / (ROLL_FIRM_FULL - ROLL_FIRM_FROM)))


@njit(cache=True)
def _above_seen(rigid, width, seen, distance):
    """Whether a tracking marker of the bone above (a distance-only point) is seen, with a learned distance to
    the member."""
    for m in range(rigid, width):
        if seen[m] and not np.isnan(distance[m]):
            return True
    return False


@njit(cache=True)
def _farthest(points, n):
    """The two of the first n points farthest apart (the steadiest line through them)."""
    best, bi, bj = -1.0, 0, 1
    for i in range(n):
        for j in range(i + 1, n):
            d = ((points[i] - points[j]) ** 2).sum()
            if d > best:
                best, bi, bj = d, i, j
    return bi, bj


@njit(cache=True)
def _partners(reference, k, rigid):
    """How many partners member k's reference holds (seen with it in that frame)."""
    n = 0
    for m in range(rigid):
        if m != k and vfinite(reference[m]):
            n += 1
    return n


@njit(cache=True)
def _spread(points, n):
    """RMS distance of the first n points from their best line: near 0, the rotation about it is free."""
    c = np.zeros(3)
    for i in range(n):
        c += points[i]
    c /= n
    scatter = np.zeros((3, 3))
    for i in range(n):
        scatter += np.outer(points[i] - c, points[i] - c)
    return np.sqrt(max(np.linalg.eigvalsh(scatter)[1], 0.0) / n)


@njit(cache=True)
def _learn_distances(lm, seg, width, refined, seen, rebuilt, distance):
    """Follow each refined member's distance to every other point while both are measured."""
    for k in range(refined):
        if not seen[k] or rebuilt[seg[k]]:
            continue
        for m in range(width):
            if m != k and seen[m] and not rebuilt[seg[m]]:
                d = np.sqrt(((lm[seg[k]] - lm[seg[m]]) ** 2).sum())
                distance[k, m] = follow(distance[k, m], d, DISTANCE_RATE)


@njit(cache=True)
def _keep_distances(p, segment, distance, prior, held_from):
    """Gauss-Newton: the point nearest the estimate ``p`` (weight ``prior``) that keeps its learned
    distances to the seen points (``held_from`` >= 0: to the tracking markers from that point on);
    unchanged unless a distance-only point is seen."""
    lm, seg, rigid, width, seen = segment
    if not _above_seen(rigid, width, seen, distance):
        return p
    q = p.copy()
    for _ in range(10):
        a = prior * np.eye(3)
        g = prior * (q - p)
        for m in range(width):
            if not seen[m] or np.isnan(distance[m]) or (held_from >= 0 and (m < held_from or seg[m] < N_LANDMARKS)):
                continue
            v = q - lm[seg[m]]
            n = np.sqrt((v ** 2).sum())
            if n < 1e-9:
                continue
            j = v / n
            a += np.outer(j, j)
            g += j * (n - distance[m])
        step = np.linalg.solve(a, g)
        q = q - step
        if (step ** 2).sum() < 1e-14:  # converged (0.1 um)
            break
    return q
