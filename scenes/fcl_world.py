"""The python-fcl collision world, built from the same scene and model files as the Drake scene.

It answers three questions for the sampling planners, the validator and the metrics:
- is a configuration collision-free (robot vs scene, and robot self-collision)?
- what is the signed clearance between robot (with a held can) and scene, in metres?
- is the straight joint-space motion between two configurations free at a given resolution?

Speed comes from doing the Python bookkeeping in a few numpy calls: forward kinematics for all
links at once (`RobotModel.link_poses`), then a conservative prefilter with bounding spheres
against the scene's axis-aligned boxes and between robot parts, and exact FCL queries only for
the few pairs the prefilter cannot clear. Batches of states (motions, paths) go through the same
path vectorized over states.

Filtering mirrors the Drake scene: pairs joined by a joint, the always-touching pairs of
`robot_model.ALWAYS_TOUCHING`, the rigid gripper assembly (link 7, gripper body, fingers, held
can), the base link against the static world, and the held can against the plate it was lifted
from.
"""

from __future__ import annotations

import math

import fcl
import numpy as np

from scenes.robot_model import RobotModel, Shape, load_robot
from scenes.scene import HeldCan, Scene

#: Bodies that form one rigid assembly with the gripper (Drake filters welded assemblies).
GRIPPER_ASSEMBLY = frozenset({"iiwa_link_7", "body", "left_finger", "right_finger", "held_can"})
G_INDEX = 8  # index of the gripper body in RobotModel.link_poses


def _fcl_geometry(kind: str, dims) -> fcl.CollisionGeometry:
    if kind == "box":
        return fcl.Box(*dims)
    if kind == "cylinder":
        return fcl.Cylinder(dims[0], dims[1])
    if kind == "capsule":
        return fcl.Capsule(dims[0], dims[1])
    if kind == "sphere":
        return fcl.Sphere(dims[0])
    raise ValueError(f"unsupported shape {kind!r}")


def _cover_spheres(kind: str, dims) -> tuple[np.ndarray, np.ndarray]:
    """Spheres (centres in the shape frame, radii) that together enclose the shape.

    A cylinder or capsule of radius r and length L is cut into k slices of length 2h; a slice
    lies within sqrt(r^2 + h^2) of its centre. A capsule's end caps lie within r of the segment's
    end points.
    """
    if kind == "box":
        return np.zeros((1, 3)), np.array([0.5 * math.sqrt(sum(d * d for d in dims))])
    if kind == "sphere":
        return np.zeros((1, 3)), np.array([dims[0]])
    r, length = dims
    k = max(1, math.ceil(length / (1.5 * r)))
    h = length / (2 * k)
    z = -length / 2 + h + 2 * h * np.arange(k)
    centres = np.column_stack([np.zeros(k), np.zeros(k), z])
    radii = np.full(k, math.sqrt(r * r + h * h))
    if kind == "capsule":
        centres = np.vstack([centres, [[0.0, 0.0, -length / 2], [0.0, 0.0, length / 2]]])
        radii = np.concatenate([radii, [r, r]])
    return centres, radii


class _Part:
    __slots__ = ("name", "body", "X_BS", "obj", "geom")

    def __init__(self, name: str, body: int, X_BS: np.ndarray, geom: fcl.CollisionGeometry):
        self.name, self.body, self.X_BS, self.geom = name, body, X_BS, geom
        self.obj = fcl.CollisionObject(geom, fcl.Transform())


class CollisionWorld:
    """Robot + scene collision queries with python-fcl.

    Args:
        scene: the scene (static boxes from its spec, cans as cylinders).
        robot: the robot model (the project's own, by default).
        gripper_opening_m: finger opening (the spec's open width by default).
        held: a can carried in the gripper; it is part of the robot and not on the plate.
        removed_can_ids: cans no longer on the plate (already recycled).
    """

    def __init__(
        self,
        scene: Scene,
        *,
        robot: RobotModel | None = None,
        gripper_opening_m: float | None = None,
        held: HeldCan | None = None,
        removed_can_ids=(),
    ) -> None:
        self.scene = scene
        self.robot = robot = robot or load_robot()
        spec = scene.spec
        opening = spec.grasp.open_width_m if gripper_opening_m is None else gripper_opening_m
        self.gripper_opening_m = opening
        self.held = held
        finger_X = robot.finger_offsets(opening)

        # --- robot parts (every part rides on one of the 9 FK bodies) ---
        parts: list[_Part] = []
        for sh in robot.shapes:
            if sh.body in finger_X:
                body, X_BS = G_INDEX, finger_X[sh.body] @ sh.X_BS
            else:
                body, X_BS = robot.body_index(sh.body), sh.X_BS
            parts.append(_Part(sh.body, body, X_BS, _fcl_geometry(sh.kind, sh.dims)))
        if held is not None:
            held_shape = Shape("held_can", "cylinder", (spec.can.radius_m, spec.can.height_m), held.X_GC)
            parts.append(_Part("held_can", G_INDEX, held.X_GC, _fcl_geometry("cylinder", held_shape.dims)))
        self.parts = parts
        sph_c, sph_r, sph_part = [], [], []
        for i, p in enumerate(parts):
            if p.name == "held_can":
                kind, dims = "cylinder", (spec.can.radius_m, spec.can.height_m)
            else:
                sh = next(s for s in robot.shapes if s.body == p.name and np.allclose(
                    (finger_X[s.body] @ s.X_BS) if s.body in finger_X else s.X_BS, p.X_BS))
                kind, dims = sh.kind, sh.dims
            c, r = _cover_spheres(kind, dims)
            c_B = (p.X_BS[:3, :3] @ c.T).T + p.X_BS[:3, 3]
            sph_c.append(c_B)
            sph_r.append(r)
            sph_part += [i] * len(r)
        self._sph_c = np.vstack(sph_c)  # sphere centres in their body frame
        self._sph_r = np.concatenate(sph_r)
        self._sph_part = np.array(sph_part)
        self._sph_body = np.array([parts[i].body for i in sph_part])

        # --- scene objects ---
        self.obstacles: list[tuple[str, fcl.CollisionObject]] = []
        lo, hi = [], []
        for name, box in spec.static_boxes().items():
            c = np.asarray(box.center_m)
            h = np.asarray(box.size_m) / 2
            self.obstacles.append((name, fcl.CollisionObject(fcl.Box(*box.size_m), fcl.Transform(c))))
            lo.append(c - h)
            hi.append(c + h)
        removed = set(removed_can_ids) | ({held.can.id} if held is not None else set())
        r_can, h_can = spec.can.radius_m, spec.can.height_m
        for can in scene.cans:
            if can.id in removed:
                continue
            X = can.X_WC()
            self.obstacles.append(
                (f"can_{can.id}", fcl.CollisionObject(fcl.Cylinder(r_can, h_can), fcl.Transform(X[:3, :3], X[:3, 3])))
            )
            axis = X[:3, 2]
            ext = np.abs(axis) * h_can / 2 + r_can * np.sqrt(np.maximum(0.0, 1 - axis**2))
            lo.append(X[:3, 3] - ext)
            hi.append(X[:3, 3] + ext)
        self._lo = np.array(lo)
        self._hi = np.array(hi)

        # --- which (part, obstacle) and (part, part) pairs count ---
        n_parts, n_obs = len(parts), len(self.obstacles)
        allowed = np.ones((n_parts, n_obs), bool)
        for i, p in enumerate(parts):
            if p.name == "iiwa_link_0":
                allowed[i, :] = False  # the base is welded to the static world
            if p.name == "held_can":
                for k, (oname, _) in enumerate(self.obstacles):
                    if oname == "plate":
                        allowed[i, k] = False  # it rests on the plate at the grasp
        self._allowed_obs = allowed
        self._sph_allowed_obs = allowed[self._sph_part]  # (S, O)
        self_pairs = []
        for i in range(n_parts):
            for j in range(i + 1, n_parts):
                a, b = parts[i].name, parts[j].name
                if a == b or frozenset((a, b)) in robot.filtered_pairs:
                    continue
                if a in GRIPPER_ASSEMBLY and b in GRIPPER_ASSEMBLY:
                    continue
                self_pairs.append((i, j))
        self.self_pairs = self_pairs
        pair_set = {p: k for k, p in enumerate(self_pairs)}
        si, sj, spair = [], [], []
        for s1 in range(len(self._sph_r)):
            for s2 in range(len(self._sph_r)):
                key = (int(self._sph_part[s1]), int(self._sph_part[s2]))
                if key in pair_set:
                    si.append(s1)
                    sj.append(s2)
                    spair.append(pair_set[key])
        self._ss_i, self._ss_j = np.array(si, int), np.array(sj, int)
        self._ss_pair = np.array(spair, int)
        self._ss_thr2 = (self._sph_r[self._ss_i] + self._sph_r[self._ss_j]) ** 2
        self._req = fcl.CollisionRequest()
        self._dreq = fcl.DistanceRequest(enable_signed_distance=True)
        self.checks = 0  # state checks answered, for planner statistics

    # --- kinematics -----------------------------------------------------------------------------

    def _sphere_centres(self, X_WB: np.ndarray) -> np.ndarray:
        """World centres of all bounding spheres, (S, 3) or (M, S, 3) for a batch of poses."""
        X = X_WB[..., self._sph_body, :, :]
        return np.einsum("...ij,...j->...i", X[..., :3, :3], self._sph_c) + X[..., :3, 3]

    def _place(self, part: _Part, X_WB: np.ndarray) -> fcl.CollisionObject:
        X = X_WB[part.body] @ part.X_BS
        part.obj.setTransform(fcl.Transform(X[:3, :3], X[:3, 3]))
        return part.obj

    # --- state checks ---------------------------------------------------------------------------

    def _candidates(self, centres: np.ndarray):
        """Candidate (part, obstacle) and self pairs whose bounding spheres overlap."""
        d = np.maximum(np.maximum(self._lo - centres[..., :, None, :], centres[..., :, None, :] - self._hi), 0.0)
        near = (np.einsum("...k,...k->...", d, d) <= (self._sph_r**2)[:, None]) & self._sph_allowed_obs
        diff = centres[..., self._ss_i, :] - centres[..., self._ss_j, :]
        near_self = np.einsum("...k,...k->...", diff, diff) <= self._ss_thr2
        return near, near_self

    def _exact(self, X_WB, near: np.ndarray, near_self: np.ndarray) -> bool:
        """True if any candidate pair of one state really collides."""
        placed = {}
        sph, obs = np.nonzero(near)
        for pi, oi in {(int(self._sph_part[s]), int(o)) for s, o in zip(sph, obs)}:
            obj = placed.get(pi) or placed.setdefault(pi, self._place(self.parts[pi], X_WB))
            if fcl.collide(obj, self.obstacles[oi][1], self._req, fcl.CollisionResult()):
                return True
        for k in set(self._ss_pair[np.nonzero(near_self)[0]].tolist()):
            i, j = self.self_pairs[k]
            oi = placed.get(i) or placed.setdefault(i, self._place(self.parts[i], X_WB))
            oj = placed.get(j) or placed.setdefault(j, self._place(self.parts[j], X_WB))
            if fcl.collide(oi, oj, self._req, fcl.CollisionResult()):
                return True
        return False

    def is_free(self, q: np.ndarray) -> bool:
        """True if configuration q (7,) rad is free of scene and self collisions."""
        self.checks += 1
        X_WB = self.robot.link_poses(q)
        near, near_self = self._candidates(self._sphere_centres(X_WB))
        if not near.any() and not near_self.any():
            return True
        return not self._exact(X_WB, near, near_self)

    def first_collision(self, Q: np.ndarray) -> int:
        """Index of the first colliding configuration of a batch (M, 7), or -1 if all are free."""
        Q = np.atleast_2d(np.asarray(Q, float))
        self.checks += len(Q)
        X_WB = self.robot.link_poses(Q)
        near, near_self = self._candidates(self._sphere_centres(X_WB))
        flagged = near.any(axis=(1, 2)) | near_self.any(axis=1)
        for m in np.nonzero(flagged)[0]:
            if self._exact(X_WB[m], near[m], near_self[m]):
                return int(m)
        return -1

    def states_free(self, Q: np.ndarray) -> np.ndarray:
        """Boolean (M,) array: which configurations of a batch are free."""
        Q = np.atleast_2d(np.asarray(Q, float))
        self.checks += len(Q)
        X_WB = self.robot.link_poses(Q)
        near, near_self = self._candidates(self._sphere_centres(X_WB))
        out = np.ones(len(Q), bool)
        for m in np.nonzero(near.any(axis=(1, 2)) | near_self.any(axis=1))[0]:
            out[m] = not self._exact(X_WB[m], near[m], near_self[m])
        return out

    # --- motions --------------------------------------------------------------------------------

    @staticmethod
    def interpolate(path: np.ndarray, resolution_rad: float) -> np.ndarray:
        """Straight joint-space segments between waypoints, sampled so that no joint moves more
        than `resolution_rad` between consecutive samples. Includes every waypoint."""
        path = np.atleast_2d(np.asarray(path, float))
        if len(path) == 1:
            return path.copy()
        out = [path[:1]]
        for a, b in zip(path[:-1], path[1:]):
            n = max(1, math.ceil(float(np.max(np.abs(b - a))) / resolution_rad))
            t = np.arange(1, n + 1)[:, None] / n
            out.append(a + t * (b - a))
        return np.vstack(out)

    def motion_free(self, q0: np.ndarray, q1: np.ndarray, *, resolution_rad: float) -> bool:
        """True if the straight motion q0 -> q1 is free at the given joint resolution."""
        return self.first_collision(self.interpolate(np.array([q0, q1]), resolution_rad)[1:]) < 0

    def path_free(self, path: np.ndarray, *, resolution_rad: float) -> int:
        """-1 if the whole piecewise-straight path is free, else the index of the first bad sample
        of `interpolate(path, resolution_rad)`."""
        return self.first_collision(self.interpolate(path, resolution_rad))

    # --- clearance ------------------------------------------------------------------------------

    def clearance(self, q: np.ndarray) -> float:
        """Signed distance (metres) between the robot (with a held can) and the scene.

        Negative in penetration (FCL's signed distance, enabled explicitly: by default
        python-fcl reports -1 for any colliding pair). Exact FCL distances are computed only for
        pairs whose bounding-sphere lower bound could beat the best found so far.
        """
        X_WB = self.robot.link_poses(q)
        c = self._sphere_centres(X_WB)
        d = np.maximum(np.maximum(self._lo - c[:, None, :], c[:, None, :] - self._hi), 0.0)
        lb_s = np.sqrt(np.einsum("sok,sok->so", d, d)) - self._sph_r[:, None]
        lb_s = np.where(self._sph_allowed_obs, lb_s, np.inf)
        n_parts = len(self.parts)
        lb = np.full((n_parts, len(self.obstacles)), np.inf)
        np.minimum.at(lb, self._sph_part, lb_s)
        order = np.argsort(lb, axis=None)
        best = np.inf
        for flat in order:
            pi, oi = divmod(int(flat), len(self.obstacles))
            if lb[pi, oi] >= best or not np.isfinite(lb[pi, oi]):
                break
            obj = self._place(self.parts[pi], X_WB)
            dist = fcl.distance(obj, self.obstacles[oi][1], self._dreq, fcl.DistanceResult())
            best = min(best, float(dist))
        return best

    def clearances(self, Q: np.ndarray) -> np.ndarray:
        """Signed clearance (metres) of each configuration of a batch (M, 7)."""
        return np.array([self.clearance(q) for q in np.atleast_2d(Q)])
