"""Joint localization: joint centres and bone frames from landmarks (thesis 3.4, facts section 7).

Input: landmark positions (frames x LANDMARKS x 3, metres, NaN = not seen), from a marker-set
profile. Output: every joint of the skeleton model with a position, a bone frame and a status.
A joint whose landmarks are missing is reported missing; it is never invented here (IK fills it).

All formulas are written in a right-handed world frame with physical directions ("right",
"forward", "medial") built from the markers, so any right-handed, any-up-axis recording works.
The thesis's code ran in Unity's left-handed frame; where a cross product's sign therefore
changes, the physical direction is what we keep (see docs/solving.md, "Localization").

Per-subject estimates (chest depth, shoulder width, height, mass) are running means over the
frames seen so far (facts 7.3). They live in :class:`BodyEstimate`, owned by the caller, so the
live node and the offline batch give the same numbers. Unlike the 2018 code, the height is a true
running mean of the samples (the original's estimate drifted towards 175 cm).

The per-frame work is one numba kernel (``_localize_frame``): the live node localizes one frame
at a time and numpy's per-call overhead made that 100x slower than the 50 us budget.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from mocap_core.ik.kernels import mtv, mv, vcross, vdot, vnorm
from mocap_core.profiles import LANDMARK_INDEX as _L
from mocap_core.profiles import BodyMeasurements
from mocap_core.skeleton import INDEX as _J
from mocap_core.skeleton import ESTIMATED, LOCATED, MISSING, N_JOINTS

# Constants of the original code (facts 7.2), metres.
MARKER_TO_SPINE_M = 0.08
NECK_ABOVE_STERNUM_M = 2 * 0.0236
HEAD_TOP_ABOVE_HEAD_M = 2 * 0.04
BMI = 24.0
DEFAULT_HEIGHT_CM = 175.0
DEFAULT_CHEST_DEPTH_MM = 170.0
DEFAULT_HALF_SHOULDER_WIDTH_MM = 200.0
# Below this bend (sine of the angle between the two segments) a limb's flexion axis is unreliable
# and the width fallbacks lean on the pelvis/chest lateral axis instead (blend up to +0.25).
STRAIGHT_SIN = 0.17

# The landmarks that locate each limb joint (both sides), for `mocap eval gaps --remove` and for
# reporting joints from rebuilt landmarks as estimated.
JOINT_LANDMARKS = {
    "elbow": ("HLE", "HME"), "wrist": ("RSP", "USP"), "hand": ("HM2",), "shoulder": ("SAE",),
    "knee": ("FLE", "FME", "TTC"), "ankle": ("FAL", "TAM"), "foot": ("FCC",), "toe": ("FM2",),
}
JOINT_OF_LANDMARK = np.zeros((N_JOINTS, len(_L)), np.int64)  # joint x landmark: 1 = locates it
for _base, _names in JOINT_LANDMARKS.items():
    for _s in "LR":
        for _name in _names:
            JOINT_OF_LANDMARK[_J[f"{_base}_{_s.lower()}"], _L[f"{_s}_{_name}"]] = 1
# Landmark and joint indices as plain ints, frozen into the compiled kernel.
SACR, L_IAS, R_IAS, TV12, TV2, SME, SGL = (_L[n] for n in ("SACR", "L_IAS", "R_IAS", "TV12", "TV2", "SME", "SGL"))
HEAD_MARK = np.array([_L["L_HEAD"], _L["R_HEAD"]])
SIDE_MARKS = np.array([[_L[f"{s}_{n}"] for n in ("SAE", "HLE", "HME", "RSP", "USP", "HM2", "FLE", "FME", "TTC",
                                                  "FAL", "TAM", "FCC", "FM2")] for s in "LR"])
M_SAE, M_HLE, M_HME, M_RSP, M_USP, M_HM2, M_FLE, M_FME, M_TTC, M_FAL, M_TAM, M_FCC, M_FM2 = range(13)
J_PELVIS, J_SPINE0, J_SPINE1, J_SPINE3, J_NECK, J_HEAD, J_HEAD_TOP = (
    _J[n] for n in ("pelvis", "spine0", "spine1", "spine3", "neck", "head", "head_top"))
SIDE_JOINTS = np.array([[_J[f"{n}_{s}"] for n in ("clavicle", "shoulder", "elbow", "wrist", "hand", "hip", "knee",
                                                   "ankle", "foot", "toe")] for s in "lr"])
S_CLAV, S_SHOULDER, S_ELBOW, S_WRIST, S_HAND, S_HIP, S_KNEE, S_ANKLE, S_FOOT, S_TOE = range(10)


@dataclass
class BodyEstimate:
    """Running sums for the subject's measurements (facts 7.3). One per actor, kept across frames.

    ``sums``: TV2->SME in the chest frame (3, metres), half shoulder width (mm), height (cm);
    ``counts``: how many valid samples each sum holds."""

    sums: np.ndarray = field(default_factory=lambda: np.zeros(5))
    counts: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass
class Localized:
    positions: np.ndarray   # (F, J, 3) metres, NaN = missing
    frames: np.ndarray      # (F, J, 3, 3) bone frames (columns x, y, z), NaN where unknown
    status: np.ndarray      # (F, J) uint8, Status.LOCATED or Status.MISSING
    height_cm: np.ndarray   # (F,) the body estimates used per frame
    mass_kg: np.ndarray
    chest_depth_mm: np.ndarray
    half_shoulder_width_mm: np.ndarray


class Localizer:
    """Turns landmark frames into located joints. Keep one per actor: it owns the body estimates."""

    def __init__(self, body: BodyMeasurements | None = None):
        self.body = body or BodyMeasurements()
        self.estimate = BodyEstimate()
        b = self.body
        self._body = np.array([np.nan if b.height_cm is None else b.height_cm,
                               np.nan if b.mass_kg is None else b.mass_kg,
                               b.marker_diameter_mm / 2000, b.elbow_width_mm / 2000,
                               b.knee_width_mm / 2000, b.ankle_width_mm / 2000])

    def localize(self, landmarks: np.ndarray, rebuilt: np.ndarray | None = None) -> Localized:
        """``rebuilt``: (F, n_landmarks) mask of landmarks that were rebuilt, not seen
        (mocap_core.segment_rebuild); the joints they give are reported estimated, not located."""
        lm = np.ascontiguousarray(landmarks, dtype=np.float64)
        if lm.ndim == 2:
            lm = lm[None]
        n = lm.shape[0]
        pos = np.empty((n, N_JOINTS, 3))         # the kernel writes every joint
        frames = np.empty((n, N_JOINTS, 3, 3))
        status = np.empty((n, N_JOINTS), np.uint8)
        body_used = np.empty((n, 4))
        _localize_batch(lm, pos, frames, status, body_used, self._body, self.estimate.sums, self.estimate.counts)
        if rebuilt is not None and rebuilt.any():
            status[((rebuilt.reshape(n, -1) @ JOINT_OF_LANDMARK.T) > 0) & (status == LOCATED)] = ESTIMATED
        return Localized(pos, frames, status, *body_used.T)


# -- kernel helpers ---------------------------------------------------------------------------------------
@njit(cache=True)
def _ok(v):
    return np.isfinite(v[0]) and np.isfinite(v[1]) and np.isfinite(v[2])


@njit(cache=True)
def _unit(v):
    n = vnorm(v)
    if not n > 1e-9:
        return np.full(3, np.nan)
    return v / n


@njit(cache=True)
def _reject(v, unit_axis):
    return v - vdot(v, unit_axis) * unit_axis


@njit(cache=True)
def _frame(x, y, z):
    f = np.empty((3, 3))
    for i in range(3):  # element by element: a slice assignment compiles numba's shape-mismatch error too
        f[i, 0], f[i, 1], f[i, 2] = x[i], y[i], z[i]
    return f


@njit(cache=True)
def _frame_yz(y, z_hint):
    """y exactly along y, z as close to z_hint as possible, x = y cross z (LookAtUp)."""
    yy = _unit(y)
    zz = _unit(_reject(z_hint, yy))
    return _frame(vcross(yy, zz), yy, zz)


@njit(cache=True)
def _frame_yx(y, x_hint):
    """y exactly along y, x as close to x_hint as possible, z = x cross y (LookAtRight)."""
    yy = _unit(y)
    xx = _unit(_reject(x_hint, yy))
    return _frame(xx, yy, vcross(xx, yy))


@njit(cache=True)
def _frame_zx(z, x_hint):
    zz = _unit(z)
    xx = _unit(_reject(x_hint, zz))
    return _frame(xx, vcross(zz, xx), zz)


@njit(cache=True)
def _first2(a, b):
    return a if _ok(a) else b


@njit(cache=True)
def _frame_ok(f):
    return np.isfinite(f).all()


@njit(cache=True)
def _bend_axis(proximal, distal, sign, medial_hint):
    """Unit medial direction of a hinge (elbow, knee), perpendicular to the proximal segment: the
    flexion axis (proximal x distal, signed medially) when bent, the trunk's lateral axis projected
    off the segment when nearly straight, blended in between."""
    flex = vcross(proximal, distal)
    denom = vnorm(proximal) * vnorm(distal)
    s = vnorm(flex) / denom if denom > 1e-12 else 0.0
    w = min(1.0, max(0.0, (s - STRAIGHT_SIN) / 0.25))
    flex_dir = _unit(flex) * sign
    if not _ok(flex_dir):
        flex_dir = np.zeros(3)
    hint = _unit(_reject(medial_hint, _unit(proximal)))
    return _unit(w * flex_dir + (1 - w) * hint)


@njit(cache=True)
def _hinge_from_lateral(parent, lateral, distal, sign, medial_hint, offset):
    """Joint centre = lateral marker + offset along the medial axis (Plug-in Gait's idea). The axis
    must be perpendicular to the parent->centre line, which passes through the unknown centre: three
    fixed-point steps settle it (like PiG's chord function)."""
    centre = lateral.copy()
    medial = np.full(3, np.nan)
    for _ in range(3):
        medial = _bend_axis(centre - parent, distal - centre, sign, medial_hint)
        centre = lateral + offset * medial
    return centre, medial


@njit(cache=True, inline="always")  # called with constants: inlined, not compiled once per constant
def _regression(fle, fal, ttc, up_shank, c1, c2, c3):
    """The thesis's knee/ankle regressions (facts 7.4): origin FLE (knee) or FAL (ankle)."""
    x = _unit(0.5 * (fle + fal) - ttc)
    if up_shank:
        z, s, origin = _unit(fle - fal), vnorm(fle - fal), fle
    else:
        z, s, origin = _unit(fal - fle), vnorm(fal - fle), fal
    e2 = vcross(z, x)
    e1 = vcross(e2, z)
    return origin + (c1 * s) * e1 + (c2 * s) * e2 + (c3 * s) * z


@njit(cache=True, inline="always")  # called with constants: inlined, not compiled once per constant
def _running(sums, counts, k0, k1, ci, sample):
    """Add a sample (NaN = none) to a running mean; return the mean (NaN before any sample)."""
    if np.isfinite(sample).all():
        sums[k0:k1] += sample
        counts[ci] += 1
    if counts[ci] == 0:
        return np.full(k1 - k0, np.nan)
    return sums[k0:k1] / counts[ci]


# -- the kernel -----------------------------------------------------------------------------------------
@njit(cache=True)
def _localize_batch(lms, pos, frames, status, body_used, body, sums, counts):
    for f in range(lms.shape[0]):
        _localize_frame(lms[f], pos[f], frames[f], body_used[f], body, sums, counts)
        for j in range(pos.shape[1]):
            status[f, j] = LOCATED if _ok(pos[f, j]) else MISSING


@njit(cache=True)
def hip_centres(lm):
    """The pelvis frame (columns: x left, y up, z forward) and the left and right hip joint centres, from
    the ASIS and the sacrum (thesis 3.4.1; Harrington et al. 2006 with the published +7.3 mm); NaN when
    one is lost."""
    sacr, lias, rias = lm[SACR], lm[L_IAS], lm[R_IAS]
    mid_asis = 0.5 * (lias + rias)
    r_hip = _frame_yx(vcross(mid_asis - sacr, lias - rias), lias - rias)
    left, up, fwd = r_hip[:, 0].copy(), r_hip[:, 1].copy(), r_hip[:, 2].copy()
    pw = vnorm(lias - rias) * 1000
    pd = vnorm(mid_asis - sacr) * 1000
    lateral = (0.33 * pw + 7.3) / 1000
    down_back = (up * (-0.30 * pw - 10.9) + fwd * (-0.24 * pd - 9.9)) / 1000
    return r_hip, mid_asis + left * lateral + down_back, mid_asis - left * lateral + down_back


@njit(cache=True, inline="always")  # its one caller is the batch: compiled once, there
def _localize_frame(lm, pos, frames, used, body, sums, counts):
    marker_r = body[2]
    r_hip, left_hip, right_hip = hip_centres(lm)
    hips = (left_hip, right_hip)
    pos[J_PELVIS] = 0.5 * (hips[0] + hips[1])
    frames[J_PELVIS] = r_hip
    r_chest, sc, n_vec = _trunk(lm, pos, frames, r_hip, hips, sums, counts)
    _head(lm, pos, frames, sc, r_chest)
    height, mass, cd, sw = _body_sizes(lm, body, n_vec, sums, counts)
    used[0], used[1], used[2], used[3] = height, mass, cd, sw
    # shoulders (3.4.2; Campbell et al. 2009) from the acromion, in the chest frame: medial, up, forward
    acromion_to_joint = ((96.2 - 0.302 * cd - 0.364 * height + 0.385 * mass) / 1000,
                         (-66.32 + 0.30 * cd - 0.432 * mass) / 1000,
                         (66.468 - 0.531 * sw + 0.571 * mass) / 1000)
    for side in range(2):
        _arm(lm, pos, frames, side, sc, r_chest, acromion_to_joint, body[3] + marker_r)
        _leg(lm, pos, frames, side, r_hip, hips, body[4] + marker_r, body[5] + marker_r)
    # a joint whose position could not be computed is missing, frame included
    for j in range(pos.shape[0]):
        if not _ok(pos[j]):
            pos[j] = np.nan
            frames[j] = np.nan


@njit(cache=True, inline="always")
def _trunk(lm, pos, frames, r_hip, hips, sums, counts):
    """The chest frame (facts 7.4 ChestOrientation), the sternum-clavicle point and the spine (3.4.3); returns
    the chest frame, the sternum-clavicle point and the running neck-to-chest vector in the chest frame."""
    sacr, tv2, tv12, sme = lm[SACR], lm[TV2], lm[TV12], lm[SME]
    lsae, rsae = lm[SIDE_MARKS[0, M_SAE]], lm[SIDE_MARKS[1, M_SAE]]
    left, up, fwd = r_hip[:, 0].copy(), r_hip[:, 1].copy(), r_hip[:, 2].copy()
    chest_y = 0.5 * (lsae + rsae) - sacr
    for cand in (0.5 * (tv2 + tv12) - sacr, tv2 - sacr, tv12 - sacr, up):
        chest_y = _first2(chest_y, cand)
    chest_x = lsae - rsae
    for cand in (0.5 * (sme + tv2) - rsae, lsae - 0.5 * (sme + tv2), left):
        chest_x = _first2(chest_x, cand)
    r_chest = _frame_yx(chest_y, chest_x)
    c_fwd = r_chest[:, 2].copy()
    neck_to_chest = mtv(r_chest, sme - tv2)
    n_vec = _running(sums, counts, 0, 3, 0, neck_to_chest)
    n_world = mv(r_chest, n_vec)
    sc = sme - 0.5 * n_world
    for cand in (tv2 + 0.5 * n_world, tv2 + MARKER_TO_SPINE_M * c_fwd, 0.5 * (lsae + rsae)):
        sc = _first2(sc, cand)
    spine0 = sacr + MARKER_TO_SPINE_M * fwd
    spine1 = tv12 + MARKER_TO_SPINE_M * fwd
    pos[J_SPINE0], frames[J_SPINE0] = spine0, _frame_yz(_first2(spine1, sc) - spine0, fwd)
    pos[J_SPINE1], frames[J_SPINE1] = spine1, _frame_yx(sc - spine1, hips[0] - hips[1])
    pos[J_SPINE3], frames[J_SPINE3] = sc, r_chest
    return r_chest, sc, n_vec


@njit(cache=True, inline="always")
def _head(lm, pos, frames, sc, r_chest):
    """The neck above the sternum-clavicle point and the head (3.4.4); without a forehead marker the head's up
    axis is neck->head."""
    neck = sc + NECK_ABOVE_STERNUM_M * r_chest[:, 1].copy()
    lhead, rhead, sgl = lm[HEAD_MARK[0]], lm[HEAD_MARK[1]], lm[SGL]
    head = 0.5 * (lhead + rhead)
    r_head = _frame_zx(sgl - head, lhead - rhead)
    if not _frame_ok(r_head):
        r_head = _frame_yx(head - neck, lhead - rhead)
    pos[J_NECK], frames[J_NECK] = neck, _frame_yz(head - neck, r_chest[:, 2].copy())
    pos[J_HEAD], frames[J_HEAD] = head, r_head
    pos[J_HEAD_TOP], frames[J_HEAD_TOP] = head + HEAD_TOP_ABOVE_HEAD_M * r_head[:, 1], r_head


@njit(cache=True, inline="always")
def _body_sizes(lm, body, n_vec, sums, counts):
    """(height cm, mass kg, chest depth mm, half shoulder width mm) (facts 7.3): the profile's where it gives
    them, else running means of this stream's samples, else the defaults."""
    height_given, mass_given = body[0], body[1]
    sacr, lias, rias, tv2, sgl = lm[SACR], lm[L_IAS], lm[R_IAS], lm[TV2], lm[SGL]
    lsae, rsae = lm[SIDE_MARKS[0, M_SAE]], lm[SIDE_MARKS[1, M_SAE]]
    cd = vnorm(n_vec) * 1000 if _ok(n_vec) else DEFAULT_CHEST_DEPTH_MM
    sw = _running(sums, counts, 3, 4, 1, np.array([vnorm(lsae - rsae) * 500]))[0]
    if not np.isfinite(sw):
        sw = DEFAULT_HALF_SHOULDER_WIDTH_MM
    if np.isfinite(height_given):
        height = height_given
    else:
        R, Lt = SIDE_MARKS[1], SIDE_MARKS[0]
        leg = vnorm(lm[R[M_FAL]] - lm[R[M_FLE]]) + vnorm(lm[R[M_FLE]] - rias)
        if not np.isfinite(leg):
            leg = vnorm(lm[Lt[M_FAL]] - lm[Lt[M_FLE]]) + vnorm(lm[Lt[M_FLE]] - lias)
        trunk = vnorm(sacr - tv2) + vnorm(tv2 - sgl)
        if not np.isfinite(trunk):
            trunk = vnorm(sacr - _first2(sgl, 0.5 * (lm[HEAD_MARK[0]] + lm[HEAD_MARK[1]])))
        sample = (leg + trunk) * 100
        if not sample < 250:
            sample = np.nan
        height = _running(sums, counts, 4, 5, 2, np.array([sample]))[0]
        if not np.isfinite(height):
            height = DEFAULT_HEIGHT_CM
    mass = mass_given if np.isfinite(mass_given) else (height / 100) ** 2 * BMI
    return height, mass, cd, sw


@njit(cache=True, inline="always")
def _arm(lm, pos, frames, side, sc, r_chest, acromion_to_joint, elbow_off):
    """One arm (3.4.2, 3.4.6, 3.4.7): the clavicle from the sternum-clavicle point, the shoulder from the
    acromion (``acromion_to_joint``: medial, up, forward in the chest frame), the elbow, wrist and hand."""
    M, J = SIDE_MARKS[side], SIDE_JOINTS[side]
    arm_sign = 1.0 if side == 0 else -1.0          # flexion-axis sign that points medially
    c_left, c_up, c_fwd = r_chest[:, 0].copy(), r_chest[:, 1].copy(), r_chest[:, 2].copy()
    medial_trunk = -c_left if side == 0 else c_left
    gx, gy, gz = acromion_to_joint
    shoulder = lm[M[M_SAE]] + gx * medial_trunk + gy * c_up + gz * c_fwd
    hle, hme, rsp, usp, hand = lm[M[M_HLE]], lm[M[M_HME]], lm[M[M_RSP]], lm[M[M_USP]], lm[M[M_HM2]]
    wrist = 0.5 * (rsp + usp)
    elbow_fb, medial_fb = _hinge_from_lateral(shoulder, hle, wrist, arm_sign, medial_trunk, elbow_off)
    medial = _first2(_unit(hme - hle), medial_fb)
    elbow = _first2(0.5 * (hle + hme), elbow_fb)
    right = medial if side == 0 else -medial
    radial = rsp - usp
    if vnorm(radial) < 1e-6:  # one marker at the wrist (both styloids on it): the forearm's roll from the elbow's axis
        radial = -medial
    r_wrist = _frame_yz(hand - wrist, radial)
    pos[J[S_CLAV]], frames[J[S_CLAV]] = sc, _frame_yz(shoulder - sc, c_fwd)
    pos[J[S_SHOULDER]], frames[J[S_SHOULDER]] = shoulder, _frame_yx(elbow - shoulder, right)
    pos[J[S_ELBOW]], frames[J[S_ELBOW]] = elbow, _frame_yz(wrist - elbow, radial)
    pos[J[S_WRIST]], frames[J[S_WRIST]] = wrist, r_wrist
    pos[J[S_HAND]], frames[J[S_HAND]] = hand, r_wrist


@njit(cache=True, inline="always")
def _leg(lm, pos, frames, side, r_hip, hips, knee_off, ankle_off):
    """One leg (3.4.5, 3.4.7): hip, knee, ankle, foot and toe."""
    M, J = SIDE_MARKS[side], SIDE_JOINTS[side]
    arm_sign = 1.0 if side == 0 else -1.0
    left = r_hip[:, 0].copy()
    medial_pelvis = -left if side == 0 else left
    hip = hips[side]
    fle, fme, ttc = lm[M[M_FLE]], lm[M[M_FME]], lm[M[M_TTC]]
    fal, tam, fcc, fm2 = lm[M[M_FAL]], lm[M[M_TAM]], lm[M[M_FCC]], lm[M[M_FM2]]
    knee_fb, kmedial_fb = _hinge_from_lateral(hip, fle, fal, -arm_sign, medial_pelvis, knee_off)
    kmedial = _first2(_unit(fme - fle), kmedial_fb)
    # regression e2 signs: + is medial for the left knee and the right ankle (docs/solving.md)
    knee = _first2(0.5 * (fle + fme), _first2(_regression(fle, fal, ttc, True, -0.1033, arm_sign * 0.09814, 0.0597),
                                              knee_fb))
    amedial = _first2(_unit(tam - fal), _unit(_reject(kmedial, _unit(fal - fle))))
    ankle = _first2(0.5 * (fal + tam), _first2(_regression(fle, fal, ttc, False, -0.07675, -arm_sign * 0.05482,
                                                           -0.02741), fal + ankle_off * amedial))
    foot = _first2(0.4 * fcc + 0.6 * fm2, 0.4 * ankle + 0.6 * fm2)
    kright = kmedial if side == 0 else -kmedial
    aright = amedial if side == 0 else -amedial
    r_foot = _frame_yz(fm2 - foot, knee - ankle)
    pos[J[S_HIP]], frames[J[S_HIP]] = hip, _frame_yx(knee - hip, hips[1] - hips[0])
    pos[J[S_KNEE]], frames[J[S_KNEE]] = knee, _frame_yx(ankle - knee, kright)
    pos[J[S_ANKLE]], frames[J[S_ANKLE]] = ankle, _frame_yx(foot - ankle, aright)
    pos[J[S_FOOT]], frames[J[S_FOOT]] = foot, r_foot
    pos[J[S_TOE]], frames[J[S_TOE]] = fm2, r_foot
