"""Joint localization: joint centres and bone frames from landmarks (thesis 3.4, facts section 7).

Input: landmark positions (frames x LANDMARKS x 3, metres, NaN = not seen), from a marker-set
profile. Output: every joint of the skeleton model with a position, a bone frame and a status.
A joint whose landmarks are missing is reported missing; it is never invented here (IK fills it).

All formulas are written in a right-handed world frame with physical directions ("right",
"forward", "medial") built from the markers, so any right-handed, any-up-axis recording works.
The thesis's code ran in Unity's left-handed frame; where a cross product's sign therefore
changes, the physical direction is what we keep (see the README's localization notes).

Per-subject estimates (chest depth, shoulder width, height, mass) are running means over the
frames seen so far (facts 7.3). They live in :class:`BodyEstimate`, owned by the caller, so the
live node and the offline batch give the same numbers. Unlike the 2018 code, the height is a true
running mean of the samples (the original's estimate drifted towards 175 cm).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mocap_core.geometry import cross, frame_yx, frame_yz, frame_zx, mid, norm, normalize, reject
from mocap_core.profiles import LANDMARK_INDEX, BodyMeasurements
from mocap_core.skeleton import INDEX, N_JOINTS, Status

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


@dataclass
class BodyEstimate:
    """Running sums for the subject's measurements (facts 7.3). One per actor, kept across frames."""

    chest_sum: np.ndarray = field(default_factory=lambda: np.zeros(3))  # TV2->SME in the chest frame, m
    chest_n: int = 0
    half_width_sum_mm: float = 0.0
    half_width_n: int = 0
    height_sum_cm: float = 0.0
    height_n: int = 0

    @staticmethod
    def _running(samples: np.ndarray, prev_sum, prev_n: int):
        """Per-frame running means of samples (F, ...) that may be NaN; also the new sum and count."""
        ok = ~np.isnan(samples).reshape(len(samples), -1).any(axis=1)
        vals = np.where(ok.reshape((-1,) + (1,) * (samples.ndim - 1)), samples, 0.0)
        sums = np.cumsum(vals, axis=0) + prev_sum
        counts = np.cumsum(ok) + prev_n
        with np.errstate(invalid="ignore", divide="ignore"):
            means = sums / counts.reshape((-1,) + (1,) * (samples.ndim - 1))
        means[counts == 0] = np.nan
        return means, (sums[-1] if len(sums) else prev_sum), int(counts[-1]) if len(counts) else prev_n

    def update_chest(self, samples):
        means, self.chest_sum, self.chest_n = self._running(samples, self.chest_sum, self.chest_n)
        return means

    def update_half_width(self, samples):
        means, self.half_width_sum_mm, self.half_width_n = self._running(samples, self.half_width_sum_mm,
                                                                         self.half_width_n)
        return means

    def update_height(self, samples):
        means, self.height_sum_cm, self.height_n = self._running(samples, self.height_sum_cm, self.height_n)
        return means


@dataclass
class Localized:
    positions: np.ndarray   # (F, J, 3) metres, NaN = missing
    frames: np.ndarray      # (F, J, 3, 3) bone frames (columns x, y, z), NaN where unknown
    status: np.ndarray      # (F, J) uint8, Status.LOCATED or Status.MISSING
    height_cm: np.ndarray   # (F,) the body estimates used per frame
    mass_kg: np.ndarray
    chest_depth_mm: np.ndarray
    half_shoulder_width_mm: np.ndarray


def _first(*candidates: np.ndarray) -> np.ndarray:
    """Per frame, the first candidate (F, 3) without NaN."""
    out = candidates[0].copy()
    for c in candidates[1:]:
        bad = np.isnan(out).any(axis=-1)
        out[bad] = c[bad]
    return out


def _where_ok(value: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    return _first(value, fallback)


def _bend_axis(proximal: np.ndarray, distal: np.ndarray, sign: float, medial_hint: np.ndarray) -> np.ndarray:
    """Unit medial direction of a hinge joint (elbow, knee), perpendicular to the proximal segment.

    Bent: the flexion axis (proximal x distal), signed so it points medially. Nearly straight: the
    trunk's lateral axis (``medial_hint``, already pointing medially) projected off the segment."""
    flex = cross(proximal, distal)
    with np.errstate(invalid="ignore", divide="ignore"):
        sin = norm(flex) / (norm(proximal) * norm(distal))
    w = np.clip((sin - STRAIGHT_SIN) / 0.25, 0.0, 1.0)[..., None]
    flex_dir = normalize(flex) * sign
    hint = normalize(reject(medial_hint, normalize(proximal)))
    flex_dir = np.where(np.isnan(flex_dir), 0.0, flex_dir)
    return normalize(w * flex_dir + (1 - w) * hint)


def _hinge_from_lateral(parent: np.ndarray, lateral: np.ndarray, distal: np.ndarray, sign: float,
                        medial_hint: np.ndarray, offset_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Joint centre = lateral marker + offset along the medial axis (Plug-in Gait's idea).

    The axis must be perpendicular to the parent->joint line, which passes through the unknown
    centre, not through the marker: two fixed-point steps settle it (like PiG's chord function)."""
    centre = lateral
    for _ in range(3):
        medial = _bend_axis(centre - parent, distal - centre, sign, medial_hint)
        centre = lateral + offset_m * medial
    return centre, medial


def _knee_regression(fle, fal, ttc, sign_e2):
    """Thesis knee regression (facts 7.4), e2 signed so the offset points medially."""
    x = normalize(mid(fle, fal) - ttc)
    z = normalize(fle - fal)
    s = norm(fle - fal)[..., None]
    e2 = cross(z, x)
    e1 = cross(e2, z)
    return fle + (-0.1033 * s) * e1 + (sign_e2 * 0.09814 * s) * e2 + (0.0597 * s) * z


def _ankle_regression(fle, fal, ttc, sign_e2):
    """Thesis ankle regression (facts 7.4, "from Visual3D"), e2 signed so the offset points medially."""
    x = normalize(mid(fle, fal) - ttc)
    z = normalize(fal - fle)
    s = norm(fal - fle)[..., None]
    e2 = cross(z, x)
    e1 = cross(e2, z)
    return fal + (-0.07675 * s) * e1 + (sign_e2 * 0.05482 * s) * e2 + (-0.02741 * s) * z


class Localizer:
    """Turns landmark frames into located joints. Keep one per actor: it owns the body estimates."""

    def __init__(self, body: BodyMeasurements | None = None):
        self.body = body or BodyMeasurements()
        self.estimate = BodyEstimate()

    def localize(self, landmarks: np.ndarray) -> Localized:
        lm = np.asarray(landmarks, dtype=np.float64)
        if lm.ndim == 2:
            lm = lm[None]
        n = lm.shape[0]
        L = {name: lm[:, i] for name, i in LANDMARK_INDEX.items()}
        pos = np.full((n, N_JOINTS, 3), np.nan)
        frames = np.full((n, N_JOINTS, 3, 3), np.nan)
        body = self.body
        marker_r_m = body.marker_diameter_mm / 2000

        def put(joint, p=None, r=None):
            if p is not None:
                pos[:, INDEX[joint]] = p
            if r is not None:
                frames[:, INDEX[joint]] = r

        # -- pelvis and hips (thesis 3.4.1; Harrington et al. 2006 with the published +7.3 mm) --------
        sacr, lias, rias = L["SACR"], L["L_IAS"], L["R_IAS"]
        mid_asis = mid(lias, rias)
        r_hip = frame_yx(cross(mid_asis - sacr, lias - rias), lias - rias)  # x left, y up, z forward
        left, up, fwd = r_hip[..., 0], r_hip[..., 1], r_hip[..., 2]
        pw = norm(lias - rias)[..., None] * 1000
        pd = norm(mid_asis - sacr)[..., None] * 1000
        lateral = (0.33 * pw + 7.3) / 1000
        down_back = (up * (-0.30 * pw - 10.9) + fwd * (-0.24 * pd - 9.9)) / 1000
        hip_l = mid_asis + left * lateral + down_back
        hip_r = mid_asis - left * lateral + down_back
        pelvis = mid(hip_l, hip_r)
        put("pelvis", pelvis, r_hip)
        put("hip_l", hip_l)
        put("hip_r", hip_r)

        # -- chest frame (facts 7.4 ChestOrientation), sternum-clavicle point, spine (3.4.3) --------
        tv2, tv12, sme = L["TV2"], L["TV12"], L["SME"]
        lsae, rsae = L["L_SAE"], L["R_SAE"]
        chest_y = _first(mid(lsae, rsae) - sacr, mid(tv2, tv12) - sacr, tv2 - sacr, tv12 - sacr, up)
        chest_x = _first(lsae - rsae, mid(sme, tv2) - rsae, lsae - mid(sme, tv2), left)
        r_chest = frame_yx(chest_y, chest_x)
        c_left, c_up, c_fwd = r_chest[..., 0], r_chest[..., 1], r_chest[..., 2]
        neck_to_chest = np.einsum("fji,fj->fi", r_chest, sme - tv2)  # in the chest frame
        n_vec = self.estimate.update_chest(neck_to_chest)
        n_world = np.einsum("fij,fj->fi", r_chest, n_vec)
        sternum_clavicle = _first(sme - 0.5 * n_world, tv2 + 0.5 * n_world, tv2 + MARKER_TO_SPINE_M * c_fwd,
                                  mid(lsae, rsae))
        spine0 = sacr + MARKER_TO_SPINE_M * fwd
        spine1 = tv12 + MARKER_TO_SPINE_M * fwd
        neck = sternum_clavicle + NECK_ABOVE_STERNUM_M * c_up
        put("spine0", spine0, frame_yz(_first(spine1, sternum_clavicle) - spine0, fwd))
        put("spine1", spine1, frame_yx(sternum_clavicle - spine1, hip_l - hip_r))
        put("spine3", sternum_clavicle, r_chest)

        # -- head (3.4.4) ----------------------------------------------------------------------------
        lhead, rhead, sgl = L["L_HEAD"], L["R_HEAD"], L["SGL"]
        head = mid(lhead, rhead)
        r_head = frame_zx(sgl - head, lhead - rhead)
        r_head = np.where(np.isnan(r_head), frame_yx(head - neck, lhead - rhead), r_head)  # no forehead marker
        put("neck", neck, frame_yz(head - neck, c_fwd))
        put("head", head, r_head)
        put("head_top", head + HEAD_TOP_ABOVE_HEAD_M * r_head[..., 1], r_head)

        # -- body estimates (facts 7.3): chest depth, half shoulder width, height, mass ----------------
        cd_mm = norm(n_vec) * 1000
        cd_mm = np.where(np.isnan(cd_mm), DEFAULT_CHEST_DEPTH_MM, cd_mm)
        sw_mm = self.estimate.update_half_width(norm(lsae - rsae) * 500)
        sw_mm = np.where(np.isnan(sw_mm), DEFAULT_HALF_SHOULDER_WIDTH_MM, sw_mm)
        if body.height_cm is not None:
            height = np.full(n, body.height_cm)
        else:
            leg = _first((norm(L["R_FAL"] - L["R_FLE"]) + norm(L["R_FLE"] - rias))[:, None],
                         (norm(L["L_FAL"] - L["L_FLE"]) + norm(L["L_FLE"] - lias))[:, None])[:, 0]
            trunk = _first((norm(sacr - tv2) + norm(tv2 - sgl))[:, None], norm(sacr - _first(sgl, head))[:, None])[:, 0]
            sample = (leg + trunk) * 100
            sample = np.where(sample < 250, sample, np.nan)
            height = self.estimate.update_height(sample[:, None])[:, 0]
            height = np.where(np.isnan(height), DEFAULT_HEIGHT_CM, height)
        mass = np.full(n, body.mass_kg) if body.mass_kg is not None else (height / 100) ** 2 * BMI

        # -- shoulders (3.4.2; Campbell et al. 2009), clavicles ------------------------------------------
        gx = (96.2 - 0.302 * cd_mm - 0.364 * height + 0.385 * mass)[:, None] / 1000   # medial
        gy = (-66.32 + 0.30 * cd_mm - 0.432 * mass)[:, None] / 1000                   # up
        gz = (66.468 - 0.531 * sw_mm + 0.571 * mass)[:, None] / 1000                  # forward
        shoulder = {"l": lsae + gx * -c_left + gy * c_up + gz * c_fwd,
                    "r": rsae + gx * c_left + gy * c_up + gz * c_fwd}

        # -- arms (3.4.6, 3.4.7) ------------------------------------------------------------------------
        elbow_offset = body.elbow_width_mm / 2000 + marker_r_m
        for s, S, sign in (("l", "L", 1.0), ("r", "R", -1.0)):
            hle, hme, rsp, usp = L[f"{S}_HLE"], L[f"{S}_HME"], L[f"{S}_RSP"], L[f"{S}_USP"]
            wrist = mid(rsp, usp)
            medial_hint = -c_left if s == "l" else c_left
            elbow_fb, medial_fb = _hinge_from_lateral(shoulder[s], hle, wrist, sign, medial_hint, elbow_offset)
            medial = _where_ok(normalize(hme - hle), medial_fb)
            elbow = _where_ok(mid(hle, hme), elbow_fb)
            hand = L[f"{S}_HM2"]
            right_hint = medial if s == "l" else -medial
            ulnar_to_radial = rsp - usp
            r_wrist = frame_yz(hand - wrist, ulnar_to_radial)
            put(f"clavicle_{s}", sternum_clavicle, frame_yz(shoulder[s] - sternum_clavicle, c_fwd))
            put(f"shoulder_{s}", shoulder[s], frame_yx(elbow - shoulder[s], right_hint))
            put(f"elbow_{s}", elbow, frame_yz(wrist - elbow, ulnar_to_radial))
            put(f"wrist_{s}", wrist, r_wrist)
            put(f"hand_{s}", hand, r_wrist)

        # -- legs (3.4.5, 3.4.7) -------------------------------------------------------------------------
        knee_offset = body.knee_width_mm / 2000 + marker_r_m
        ankle_offset = body.ankle_width_mm / 2000 + marker_r_m
        for s, S, sign, hip in (("l", "L", -1.0, hip_l), ("r", "R", 1.0, hip_r)):
            fle, fme, ttc = L[f"{S}_FLE"], L[f"{S}_FME"], L[f"{S}_TTC"]
            fal, tam, fcc, fm2 = L[f"{S}_FAL"], L[f"{S}_TAM"], L[f"{S}_FCC"], L[f"{S}_FM2"]
            medial_hint = -left if s == "l" else left
            knee_fb, medial_fb = _hinge_from_lateral(hip, fle, fal, sign, medial_hint, knee_offset)
            medial = _where_ok(normalize(fme - fle), medial_fb)
            # regression e2 signs: + is medial for the left knee and the right ankle (derivation in README)
            knee = _first(mid(fle, fme), _knee_regression(fle, fal, ttc, -sign), knee_fb)
            ankle_medial = _where_ok(normalize(tam - fal), normalize(reject(medial, normalize(fal - fle))))
            ankle = _first(mid(fal, tam), _ankle_regression(fle, fal, ttc, sign),
                           fal + ankle_offset * ankle_medial)
            foot = _first(0.4 * fcc + 0.6 * fm2, 0.4 * ankle + 0.6 * fm2)
            right_knee = medial if s == "l" else -medial
            right_ankle = ankle_medial if s == "l" else -ankle_medial
            r_foot = frame_yz(fm2 - foot, knee - ankle)
            put(f"hip_{s}", None, frame_yx(knee - hip, hip_r - hip_l))
            put(f"knee_{s}", knee, frame_yx(ankle - knee, right_knee))
            put(f"ankle_{s}", ankle, frame_yx(foot - ankle, right_ankle))
            put(f"foot_{s}", foot, r_foot)
            put(f"toe_{s}", fm2, r_foot)

        status = np.where(np.isnan(pos).any(axis=-1), Status.MISSING, Status.LOCATED).astype(np.uint8)
        return Localized(pos, frames, status, height, mass, cd_mm, sw_mm)
