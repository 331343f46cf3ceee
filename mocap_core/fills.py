"""The gap fills beyond the thesis, registered in the order they run (mocap_core.fill_units says what a fill is).
Adding one is its module, its test and its line here: its settings become the stage's options, node params and
`mocap eval gaps` flags."""
from __future__ import annotations

from mocap_core.blend import Blend
from mocap_core.body_model import BodyModelSteer
from mocap_core.end_model import EndModel
from mocap_core.leg_hinge import LegHinge
from mocap_core.limb_memory import LimbMemory
from mocap_core.pair_guard import PairGuard
from mocap_core.partial_means import PartialMeans
from mocap_core.pose_memory import PoseMemory
from mocap_core.rigid_chain import RigidChain
from mocap_core.segment_carry import SegmentCarry
from mocap_core.segment_rebuild import SegmentRebuilder
from mocap_core.swivel import Swivel

# The hip stage's, on the landmarks.
LANDMARK_FILLS = (
    PairGuard,         # drops a bony pair whose spacing jumped, for the fills after it
    SegmentRebuilder,  # lost forearm, foot and shank landmarks from their segment
    LegHinge,          # lost knees and ankles from the hip and a shank marker
    PoseMemory,        # lost knees and ankles where the take's earlier poses had them
    PartialMeans,      # a landmark that is the mean of several markers, from those still seen
)

# The IK stage's, on each limb, around Algorithm 1 (which fills what they leave lost).
LIMB_FILLS = (
    EndModel,        # a limb lost from its first joint down: its end where the body model puts it
    SegmentCarry,    # a lost ankle with its foot, a lost end with the bone before it
    LimbMemory,      # where earlier poses had a lone lost joint (steers the swivel)
    BodyModelSteer,  # where the rest of the body puts it (steers the swivel)
    Swivel,          # lost joints between two located ones, on their swivel circle
    Blend,           # after Algorithm 1: every change of source met without a twitch
    RigidChain,      # last: the limb as the subject's rigid chain fitted to what was placed
)
