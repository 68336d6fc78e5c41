"""The sweep's motion windows: every recording of the shared data folder, including the ones where
the thighs and upper arms rotate about their own axes (turning, spinning hops, kneeling).

Windows were chosen from the pelvis height and the facing direction over each file (turns of 90 to
270 degrees in 131_03 and 01_01, a kneel in 131_01), never from a tracker's result. Statics: another
take of the same subject where one exists, else standing frames of the same file outside the window.
"""

from __future__ import annotations

from realdata.body import ANATOMIES, Anatomy
from realdata.clips import ClipSpec

# CMU BVH in MotionBuilder naming (01_01.bvh): the same bones as realdata.body.CMU_BVH's, where
# 131_01's lowerback/Chest/Chest2/lowerneck/Neck are LowerBack/Spine/Spine1/Neck/Neck1 and a
# clavicle runs from LeftShoulder to LeftArm.
CMU_BVH_MOTIONBUILDER = Anatomy(
    spine=("Hips", "Spine", "Spine1"), neck=("Spine1", "Neck1", "Head"), head_top="Head_end",
    clavicle=("{side}Shoulder", "{side}Arm"), upper_arm=("{side}Arm", "{side}ForeArm"),
    forearm=("{side}ForeArm", "{side}Hand"), hand=("{side}Hand", "{S}Fingers", "{S}Fingers_end"),
    thumb=("{side}Hand", "{S}Thumb_end"), thigh=("{side}UpLeg", "{side}Leg"),
    shank=("{side}Leg", "{side}Foot"), foot=("{side}Foot", "{side}ToeBase", "{side}ToeBase_end"),
    hips=("LeftUpLeg", "RightUpLeg"), shoulders=("LeftArm", "RightArm"),
)


def anatomy_of(joint_names: list[str], source: str) -> Anatomy:
    """The anatomy naming this skeleton's bones (01_01.bvh's MotionBuilder names or the source's)."""
    if source == "cmu_bvh" and "LeftUpLeg" in joint_names:
        return CMU_BVH_MOTIONBUILDER
    return ANATOMIES[source]


# name -> window (kind: walking, turn, hop, jumps, kneel, boxing). The 131_03 windows: a hop
# turning to -76 deg and back (2.0 s), one turning to -118 deg and back (4.25 s), a hop with a
# 270-deg spin (6.25 s); 01_01: forward jumps (1.25 s), standing turns of 180 deg (8.5, 16.0 s);
# 131_01: a turn of -105 deg down to kneeling on one knee, pelvis 0.50 m high (2.25 s).
MOTIONS: dict[str, ClipSpec] = {spec.name: spec for spec in (
    ClipSpec("walk35_01", "walking", "cmu/35_01.amc", "asf", 0.0, asf="cmu/35.asf", static_file="cmu/35_02.amc"),
    ClipSpec("walk35_02", "walking", "cmu/35_02.amc", "asf", 0.5, asf="cmu/35.asf", static_file="cmu/35_01.amc"),
    ClipSpec("walk39_01", "walking", "cmu/39_01.amc", "asf", 0.0, asf="cmu/39.asf", static_start_s=2.55),
    ClipSpec("walk131_01", "walking", "bvh/131_01.bvh", "cmu_bvh", 4.3, static_file="bvh/131_02.bvh"),
    ClipSpec("kneel131_01", "kneel", "bvh/131_01.bvh", "cmu_bvh", 2.25, static_file="bvh/131_02.bvh"),
    ClipSpec("hopturn131_03a", "hop", "bvh/131_03.bvh", "cmu_bvh", 2.0, static_file="bvh/131_02.bvh"),
    ClipSpec("hopturn131_03b", "hop", "bvh/131_03.bvh", "cmu_bvh", 4.25, static_file="bvh/131_02.bvh"),
    ClipSpec("hopspin131_03", "hop", "bvh/131_03.bvh", "cmu_bvh", 6.25, static_file="bvh/131_02.bvh"),
    ClipSpec("jumps01_01", "jumps", "bvh/01_01.bvh", "cmu_bvh", 1.25, static_start_s=0.0),
    ClipSpec("turn01_01a", "turn", "bvh/01_01.bvh", "cmu_bvh", 8.5, static_start_s=0.0),
    ClipSpec("turn01_01b", "turn", "bvh/01_01.bvh", "cmu_bvh", 16.0, static_start_s=0.0),
    ClipSpec("boxing_a", "boxing", "bvh/Boxing_Toes.bvh", "boxing", 3.3),
    ClipSpec("boxing_b", "boxing", "bvh/Boxing_Toes.bvh", "boxing", 5.4),
    ClipSpec("boxing_c", "boxing", "bvh/Boxing_Toes.bvh", "boxing", 8.5),
)}
