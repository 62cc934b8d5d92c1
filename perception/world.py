"""The perceived collision world: the world a robot plans in when all it knows is its cell's fixed
parts and what its cameras see.

A `PerceivedWorld` is a `Scene` like the ground truth's, so every planner (the compiled kernels,
the python-fcl world, the Drake scene of `ik` and `trajopt`, roboplan) plans in it unchanged:

- **Known fixtures**, exact: the table, the plate, the bin and every obstacle of the spec that is
  part of the cell (walls, shelf, window frame); not the loose objects a generator scatters on the
  plate (`LOOSE_PREFIXES`: distractors and look-alikes), which the robot must see.
- **Perceived cans**: a cylinder at each detection's pose, its radius and length grown by
  `can_padding_m` (the perception's p95 pose error under the sensor: `can_padding_for`). The can
  being grasped rides in the gripper at its perceived pose.
- **Everything else seen above the plate** as merged voxel boxes (`voxel_m` cubes): the volume over
  the plate's footprint, from `floor_clearance_m` above its top to `height_m`, is cut into voxels;
  a voxel is occupied when a camera's depth point falls in it, or when no camera sees through it
  (space carving: every space hidden behind or below a seen surface, or never seen, is occupied).
  Each camera sees through a voxel when its depth at the voxel centre's pixel lies beyond the
  voxel's far side along that ray by more than `sigma_k` depth sigmas of the sensor. A run of up to
  `hole_fill_px` pixels with no depth along an image row takes the farther of the depths at its two
  ends when it is a structured-light projector's shadow (it falls on the farther surface, beside
  the nearer object on the projector's side, as wide as their disparity jump), else the nearer
  one (a dropout on an object's edge or face hides what is behind it). Longer gaps stay unseen.
- **Left out**: points explained by a known fixture (within `sigma_k` depth sigmas) or a perceived
  can (within its padding, `can_point_margin_m` and the depth tolerance), unseen space within `unseen_clear_m` of a perceived can (its own
  shadow) unless next to a voxel where something else was seen, and the robot itself at the configuration the frame was
  taken in (each robot part grown by `robot_margin_m`; a held can is part of the robot).
- **Boxes and padding**: occupied voxels are merged into boxes; each box reaches as far as what its
  voxels hold: the bounding box of a voxel's points, or the whole cube where no camera saw in,
  kept out of each perceived can's held model where it stands (`perception.voxel_boxes`). A
  box's face on a seen surface is therefore at the surface's points, one on unseen space at the
  voxel's edge (up to `voxel_m` beyond the object); a seen voxel also reaches the occupied voxels
  beside it, so an object stays solid behind its seen surface. Seen points are grown by `point_sigmas`
  sensor sigmas at their depth (at least 1 mm), unseen cubes not (they already reach past what
  hides there); the cans by their p95 pose error.

The truth judges: planners see this world, the independent validator and the physics the true one
(`suite.problems.cycle.build_problems`, `suite.run.trial`).
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from perception.geometry import back_project_camera, camera_to_world, project
from perception.voxel_boxes import clear_of_cans, merge_boxes
from perception.world_evidence import depth_sigmas, fill_row_holes, inside, robot_explains
from scenes.errors import SuiteError
from scenes.scene import CanPose, HeldCan, Scene
from scenes.spec import SceneSpec
from scenes.spec_parts import Obstacle, pose_tuple

#: name prefixes of the objects a scene generator scatters on the plate (not known to the robot)
LOOSE_PREFIXES = ("distractor_", "hourglass_", "dented_")
#: the voxel boxes' names in the perceived spec
VOXEL_PREFIX = "seen_"
#: the perceived cans' ids start here (never a ground-truth id)
PERCEIVED_ID_BASE = 1000
#: seen points are grown by at least this (a perfect sensor's surface still makes a solid box)
MIN_POINT_PADDING_M = 0.001
#: voxel boxes' colour (rendering of a perceived world)
VOXEL_RGBA = (0.55, 0.55, 0.85, 0.6)


@dataclasses.dataclass(frozen=True)
class WorldParams:
    """How the perceived world is built (see the module docstring).

    Attributes:
        voxel_m: the voxel's edge, metres.
        height_m: the top of the volume above the plate's top, metres.
        floor_clearance_m: the volume starts this far above the plate's top (the plate's own noisy
            points stay below it); an object lower than this is not seen.
        sigma_k: the tolerance of a depth, in the sensor's depth sigmas at that depth (free space,
            and points that are a fixture's or a can's).
        point_sigmas: each seen point is grown by this many depth sigmas at its own depth: a
            voxel's points scatter to both sides of the surface, so their bounding box already
            reaches past it by about their largest deviation.
        can_padding_m: growth of each perceived can's radius and half length (None: the p95 pose
            error of the pipeline under its sensor, `can_padding_for`).
        robot_margin_m: points within this of the robot's collision parts are the robot's.
        can_point_margin_m: points within this (plus the depth tolerance) of a perceived can's
            padded surface are the can's: a can seen farther off than its p95 error shows its
            surface outside its padding (a neighbour closer than this to a can is not seen).
        unseen_clear_m: space no camera saw into within this of a perceived can (beyond its
            padding) is the can's own shadow, not an obstacle (as a robot's occupancy map is cleared
            around the objects it models), unless it touches a voxel where something else was seen
            (the hidden side of that object stays occupied). It must exceed a voxel box's half size
            and padding plus a held can's margin, or a can lifted from its place starts in its own
            shadow.
        merge_tol_m: a merged box takes in a neighbouring slab of voxels only when the slab's
            faces across the merge lie within this of the box's (`perception.voxel_boxes.merge_boxes`).
        hole_fill_px: the longest run of pixels without depth along a row that is filled.
    """

    voxel_m: float = 0.01
    height_m: float = 0.30
    floor_clearance_m: float = 0.006
    sigma_k: float = 3.0
    point_sigmas: float = 1.0
    can_padding_m: float | None = None
    robot_margin_m: float = 0.02
    can_point_margin_m: float = 0.005
    unseen_clear_m: float = 0.015
    merge_tol_m: float = 0.003
    hole_fill_px: int = 24

    def __post_init__(self):
        for name in ("voxel_m", "height_m", "floor_clearance_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise SuiteError(f"perceived world: {name} must be a positive number of metres, got {v}")
        if self.can_padding_m is not None and not (math.isfinite(self.can_padding_m) and self.can_padding_m >= 0):
            raise SuiteError(f"perceived world: can padding must be >= 0 m, got {self.can_padding_m}")
        if self.voxel_m > 0.05:
            raise SuiteError(f"perceived world: voxel_m {self.voxel_m} m is coarser than a can; allowed up to 0.05")


#: p95 xy pose error (metres) measured by `perceive --evaluate` on `clutter` (docs/perception.md):
#: at most 1.39 mm on clean depth (seeds 92000-92019); under kinect-v1 at 1x its sigma at most
#: 2.10 mm independent (92000-92019) and 1.81 mm correlated over 4 or 8 px (97100-97119), either
#: pipeline; rounded up. A perceived can on the plate is grown by it. (At 2x sigma the paper's
#: pipeline reaches 4 mm: pass `WorldParams.can_padding_m` there.)
CAN_PADDING_CLEAN_M = 0.0015
CAN_PADDING_NOISY_M = 0.0025


def can_padding_for(sensor) -> float:
    """The perceived cans' padding for a sensor model (None: a perfect sensor)."""
    return CAN_PADDING_CLEAN_M if sensor is None else CAN_PADDING_NOISY_M


@dataclasses.dataclass(frozen=True)
class PerceivedWorld:
    """A world built from camera frames.

    Attributes:
        scene: the world as a scene: known fixtures and voxel boxes in its spec's obstacles, the
            perceived cans (ids from PERCEIVED_ID_BASE) as its cans, the can model grown by the padding.
        can_of_detection: detection id -> the perceived can's id.
        voxels: occupied voxels (after what is explained is left out); boxes: voxel boxes;
            boxes_cleared: boxes moved back (or dropped) off a perceived can's held model.
        params: how it was built; cameras: the frames it fused; build_time_s: seconds.
        can_padding_m, voxel_padding_m: the padding of the cans, and of the boxes beyond their cubes.
    """

    scene: Scene
    can_of_detection: dict[int, int]
    voxels: int
    boxes: int
    boxes_cleared: int
    params: WorldParams
    cameras: tuple[str, ...]
    build_time_s: float
    can_padding_m: float
    voxel_padding_m: float

    def can(self, detection_id: int) -> CanPose:
        cid = self.can_of_detection[detection_id]
        return next(c for c in self.scene.cans if c.id == cid)

    def held(self, detection_id: int, X_WG: np.ndarray) -> HeldCan:
        """The perceived can of a detection as it sits in a gripper closed on it at X_WG."""
        return HeldCan.from_grasp(self.can(detection_id), X_WG)

    def summary(self) -> dict:
        return {"world": "perceived", "voxel_m": self.params.voxel_m, "voxels": self.voxels, "boxes": self.boxes,
                "boxes_cleared": self.boxes_cleared,
                "cans": len(self.scene.cans), "cameras": list(self.cameras),
                "can_padding_m": self.can_padding_m, "voxel_padding_m": round(self.voxel_padding_m, 6),
                "build_time_s": round(self.build_time_s, 4)}


def fixtures(spec: SceneSpec) -> tuple[Obstacle, ...]:
    """The spec's obstacles a robot cell knows (everything but the loose objects on the plate)."""
    return tuple(o for o in spec.extra if not o.name.startswith(LOOSE_PREFIXES))


def build_world(
    spec: SceneSpec,
    frames: dict,
    detections,
    *,
    seed: int,
    sensor=None,
    q_robot: np.ndarray | None = None,
    held: HeldCan | None = None,
    gripper_opening_m: float | None = None,
    params: WorldParams = WorldParams(),
) -> PerceivedWorld:
    """The perceived world of sensed frames (camera name -> `CameraImage`, depth NaN where none)
    and the detections in them (see the module docstring).

    Args:
        spec: the cell (its fixtures, plate and can model; no loose object is read from it).
        frames: every camera's frame as the sensor returned it.
        detections: the cans perceived (`CanDetection`s), each becoming a can of the world.
        seed: the scene's seed (the world's scene carries it).
        sensor: the frames' sensor model (`scenes.sensor.SensorSpec`; None: a perfect sensor).
        q_robot: the arm's joints when the frames were taken (its points are left out; None: the
            arm is out of view).
        held: a can in the gripper then (left out with the robot).
        gripper_opening_m: the fingers' opening then (default: open).
        params: the builder's settings.
    """
    t0 = time.perf_counter()
    if not frames:
        raise SuiteError("a perceived world needs at least one camera frame")
    r, h = spec.can.radius_m, spec.can.height_m
    pad_c = can_padding_for(sensor) if params.can_padding_m is None else params.can_padding_m
    cans = tuple(CanPose(PERCEIVED_ID_BASE + i, tuple(float(v) for v in d.p_WC_m), bool(d.lying), float(d.axis_yaw_rad))
                 for i, d in enumerate(detections))
    by_det = {d.id: PERCEIVED_ID_BASE + i for i, d in enumerate(detections)}
    v = params.voxel_m
    # the volume over the plate's footprint
    pc, ps = np.asarray(spec.plate.center_m, float), np.asarray(spec.plate.size_m, float)
    lo = np.array([pc[0] - ps[0] / 2, pc[1] - ps[1] / 2, spec.plate_top_z_m + params.floor_clearance_m])
    shape = np.maximum(np.ceil(np.array([ps[0], ps[1], params.height_m - params.floor_clearance_m]) / v).astype(int), 1)
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), axis=-1).reshape(-1, 3)
    centres = lo + (idx + 0.5) * v
    known = fixtures(spec) + tuple(Obstacle.from_box(n, b) for n, b in spec.static_boxes().items())

    opening = spec.grasp.open_width_m if gripper_opening_m is None else gripper_opening_m

    def explained(p: np.ndarray, *, fixture_margin: float, can_margin: float) -> np.ndarray:
        hit = np.zeros(len(p), bool)
        for o in known:
            hit |= inside(p, o.shape, o.size_m, o.pose(), fixture_margin)
        for c in cans:
            hit |= inside(p, "cylinder", (r + pad_c, h + 2 * pad_c), c.X_WC(), can_margin)
        hit |= robot_explains(p, spec=spec, q=q_robot, held=held, opening_m=opening, margin_m=params.robot_margin_m)
        return hit

    # the depth sigma over the volume (the largest any camera has there) sets the depth tolerances
    sigmas = []
    for image in frames.values():
        _, zc = project(np.array([lo, lo + [ps[0], ps[1], params.height_m]]), K=image.K, X_WC=image.X_WC)
        sigmas.append(0.0 if sensor is None else max(sensor.depth_sigma_at_m(float(abs(z))) for z in zc))
    max_sigma = max(sigmas)
    point_tol = params.sigma_k * max_sigma
    pad_seen: list[float] = []  # the largest growth of a seen point, per camera
    seen_free = np.zeros(len(centres), bool)
    hit_vox = np.zeros(tuple(shape), bool)
    flat = lambda k: np.ravel_multi_index(tuple(k.T), tuple(shape))  # noqa: E731
    pt_lo = np.full((len(centres), 3), np.inf)  # each voxel's points' bounding box
    pt_hi = np.full((len(centres), 3), -np.inf)
    for image in frames.values():
        shadow = (float(image.K[0, 0]) * sensor.baseline_m
                  if sensor is not None and sensor.kind == "structured-light" else None)
        depth = fill_row_holes(image.depth_m, params.hole_fill_px, shadow_px_m=shadow)
        hgt, wid = depth.shape
        uv, zc = project(centres, K=image.K, X_WC=image.X_WC)
        u, vv = np.round(uv[:, 0]).astype(int), np.round(uv[:, 1]).astype(int)
        ok = (zc > 0) & (u >= 0) & (u < wid) & (vv >= 0) & (vv < hgt)
        d = np.full(len(centres), np.nan)
        d[ok] = depth[vv[ok], u[ok]]
        # the voxel's far side along the ray, in depth: (v/2) / max |ray direction| along the ray
        ray = centres - image.X_WC[:3, 3]
        dist = np.linalg.norm(ray, axis=1)
        exit_depth = (v / 2) / np.abs(ray / dist[:, None]).max(axis=1) * np.abs(zc) / dist
        tol = exit_depth + params.sigma_k * depth_sigmas(sensor, zc)
        with np.errstate(invalid="ignore"):
            seen_free |= ok & (d > zc + tol)  # inf (nothing within range) sees through
        # the frame's points in the volume
        p = camera_to_world(back_project_camera(image.depth_m, K=image.K), image.X_WC).reshape(-1, 3)
        p = p[np.all(np.isfinite(p), axis=1)]
        k = np.floor((p - lo) / v).astype(int)
        in_vol = np.all((k >= 0) & (k < shape), axis=1)
        p, k = p[in_vol], k[in_vol]
        keep = ~explained(p, fixture_margin=point_tol, can_margin=point_tol + params.can_point_margin_m)
        hit_vox[tuple(k[keep].T)] = True
        # each point grown by `point_sigmas` of its own depth's sigma (at least MIN_POINT_PADDING_M)
        zp = (p[keep] - image.X_WC[:3, 3]) @ image.X_WC[:3, 2]
        grow = np.maximum(params.point_sigmas * depth_sigmas(sensor, zp), MIN_POINT_PADDING_M)
        np.minimum.at(pt_lo, flat(k[keep]), p[keep] - grow[:, None])
        np.maximum.at(pt_hi, flat(k[keep]), p[keep] + grow[:, None])
        pad_seen.append(float(grow.max()) if len(grow) else 0.0)
    # unseen space next to a fixture, a can or the robot is theirs (their own shadow); points are not
    # unseen space beside a can is its own shadow, unless it touches a surface seen there (then it may
    # be the hidden side of that object: occupied)
    from scipy.ndimage import binary_dilation

    near_seen = binary_dilation(hit_vox, structure=np.ones((3, 3, 3), bool))
    shadow = ~near_seen.reshape(-1) & explained(centres, fixture_margin=0.0, can_margin=params.unseen_clear_m)
    # mostly inside a can or a fixture (its centre within half a voxel of it): theirs
    shadow |= explained(centres, fixture_margin=0.0, can_margin=v / 2)
    occ = hit_vox.reshape(-1) | (~seen_free & ~shadow)
    occ_grid = occ.reshape(tuple(shape))
    pad_v = max(pad_seen, default=MIN_POINT_PADDING_M)
    extra = list(fixtures(spec))
    n_fixed = len(extra)
    # What each occupied voxel holds: the bounding box of its points, or the whole cube when no
    # camera saw into it; a merged box is the bounding box of what its voxels hold (its faces on
    # seen surfaces are where the points are, not at the voxels' edges).
    has = hit_vox.reshape(-1)
    c_lo = np.where(has[:, None], pt_lo, centres - v / 2).reshape(*shape, 3)
    c_hi = np.where(has[:, None], pt_hi, centres + v / 2).reshape(*shape, 3)
    # a seen voxel reaches its occupied neighbours (the object stays solid: no hollow behind its
    # surface for a link to cross between two checked states); only faces on free space are tight
    v_lo, v_hi = (centres - v / 2).reshape(*shape, 3), (centres + v / 2).reshape(*shape, 3)
    for a in range(3):
        before = np.zeros(tuple(shape), bool)
        after = np.zeros(tuple(shape), bool)
        idx_b = [slice(None)] * 3
        idx_a = [slice(None)] * 3
        idx_b[a], idx_a[a] = slice(1, None), slice(None, -1)
        before[tuple(idx_b)] = occ_grid[tuple(idx_a)]  # the neighbour at -a is occupied
        after[tuple(idx_a)] = occ_grid[tuple(idx_b)]  # the neighbour at +a is occupied
        c_lo[..., a] = np.where(before, np.minimum(c_lo[..., a], v_lo[..., a]), c_lo[..., a])
        c_hi[..., a] = np.where(after, np.maximum(c_hi[..., a], v_hi[..., a]), c_hi[..., a])
    # the held model of every perceived can where it stands is the can's (`perception.voxel_boxes`),
    # grown by how far the goal IK may place it off (its position tolerance per axis, and its
    # orientation tolerance over the model's diagonal)
    from scenes.ik import IkOptions

    held_r = r + max(spec.grasp.held_margin_m, pad_c)
    held_h = h + 2 * max(spec.grasp.held_margin_m, pad_c)
    ik = IkOptions()
    slack = math.sqrt(3) * ik.position_tolerance_m + ik.orientation_tolerance_rad * math.hypot(held_h, 2 * held_r)
    held_r, held_h = held_r + slack, held_h + 2 * slack
    # each voxel first (a face moved back loses at most its own slab), then each merged box (a
    # box may reach back in by up to the merge's tolerance)
    for i in np.flatnonzero(occ):
        vi = np.unravel_index(i, tuple(shape))
        kept = clear_of_cans(c_lo[vi], c_hi[vi], cans, held_r, held_h)
        if kept is None:
            occ_grid[vi] = False
        else:
            c_lo[vi], c_hi[vi] = kept
    cleared = 0
    for start, size in merge_boxes(occ_grid, c_lo, c_hi, params.merge_tol_m):
        cut = tuple(slice(a, a + b) for a, b in zip(start, size))
        b_lo = c_lo[cut].reshape(-1, 3).min(axis=0)
        b_hi = c_hi[cut].reshape(-1, 3).max(axis=0)
        if start[2] == 0 and b_lo[2] < lo[2] + v / 2:  # it stands on the plate (below the volume nothing is seen)
            b_lo[2] = spec.plate_top_z_m
        kept = clear_of_cans(b_lo, b_hi, cans, held_r, held_h)
        if kept is None or not np.array_equal(kept[0], b_lo) or not np.array_equal(kept[1], b_hi):
            cleared += 1
        if kept is None:
            continue
        b_lo, b_hi = kept
        X = np.eye(4)
        X[:3, 3] = (b_lo + b_hi) / 2
        extra.append(Obstacle(f"{VOXEL_PREFIX}{len(extra) - n_fixed}", "box", tuple(float(s) for s in b_hi - b_lo), pose_tuple(X), VOXEL_RGBA))
    can = dataclasses.replace(spec.can, radius_m=r + pad_c, height_m=h + 2 * pad_c)
    # The can in the gripper is where the fingers hold it, not where it was seen: it keeps the
    # truth's model and margin (the padding is taken back from its margin).
    grasp = dataclasses.replace(spec.grasp, held_margin_m=max(spec.grasp.held_margin_m - pad_c, 0.0))
    world_spec = dataclasses.replace(spec, extra=tuple(extra), can=can, grasp=grasp)
    return PerceivedWorld(
        scene=Scene(world_spec, seed, cans), can_of_detection=by_det, voxels=int(occ.sum()),
        boxes=len(extra) - n_fixed, boxes_cleared=cleared, params=params, cameras=tuple(frames), build_time_s=time.perf_counter() - t0,
        can_padding_m=pad_c, voxel_padding_m=pad_v,
    )


def perceive_world(scene: Scene, *, setup, rng: np.random.Generator, images: dict | None = None,
                   q_robot: np.ndarray | None = None, held: HeldCan | None = None,
                   gripper_opening_m: float | None = None, params: WorldParams = WorldParams()):
    """Perceive a scene and build the world its planners plan in: every camera's frame through the
    setup's sensor (`perception.pipeline.PerceptionSetup`; the spec's cameras' when it names none),
    the cans detected by its pipeline in the top camera's, and the world of all of them.

    Args:
        scene: the scene (only rendered: nothing of its truth is read).
        setup: pipeline, segmentation and sensor.
        rng: the sensor noise's generator (cameras drawn in the order top, then the spec's others).
        images: clean frames already rendered (camera name -> CameraImage, every camera); None:
            rendered here with the arm at `q_robot` (default: Drake's zeros, as `render`).
        q_robot, held, gripper_opening_m: the robot when the frames were taken (left out of them).

    Returns:
        (detections, PerceivedWorld).
    """
    from perception.observe import sense
    from perception.pipeline import GRASP_CAMERA, detect
    from perception.side_view import SIDE_CAMERAS
    from scenes.render import render

    names = [GRASP_CAMERA] + [n for n in scene.spec.cameras.poses if n != GRASP_CAMERA]
    if images is None:
        images = render(scene, cameras=names, q_iiwa=q_robot)
        if q_robot is None:
            q_robot = np.zeros(7)
    sensor = setup.sensor_spec() or scene.spec.cameras.sensor
    frames = {n: images[n] if sensor is None else sense(images[n], sensor=sensor, rng=rng) for n in names if n in images}
    side = {n: im for n, im in frames.items() if n in SIDE_CAMERAS and setup.pipeline == "robust"}
    detections, _, _ = detect(frames[GRASP_CAMERA], scene.spec, params=setup.params(), pipeline=setup.pipeline,
                              side_images=side)
    world = build_world(scene.spec, frames, detections, seed=scene.seed, sensor=sensor, q_robot=q_robot, held=held,
                        gripper_opening_m=gripper_opening_m, params=params)
    return detections, world
