"""A small monocular visual odometry: KLT tracks, essential-matrix initialisation, PnP tracking against a
local map, keyframes, and a windowed bundle adjustment. Only OpenCV, NumPy and SciPy.

Honest about failure: it says NOT INITIALIZED when no two frames give a well-conditioned start, and LOST
when too few map points remain to place a frame; it never invents a pose.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares


@dataclass
class Settings:
    max_corners: int = 500
    min_corner_distance: int = 12
    quality_level: float = 0.01
    klt_window: int = 15
    klt_levels: int = 3
    fb_max_error_px: float = 1.0
    init_min_parallax_px: float = 20.0
    init_min_angle_deg: float = 3.0
    init_min_inliers: int = 60
    init_max_frames: int = 60
    pnp_reprojection_px: float = 2.5
    min_tracked_points: int = 15
    kf_max_frames: int = 15
    kf_min_parallax_px: float = 30.0
    kf_min_point_ratio: float = 0.7
    triangulation_min_angle_deg: float = 1.0
    ba_window: int = 5
    ba_max_evaluations: int = 15


def log(msg: str) -> None:
    print(msg, flush=True)


# ---------------------------------------------------------------- geometry helpers


def rodrigues_batch(rvecs: np.ndarray) -> np.ndarray:
    theta = np.linalg.norm(rvecs, axis=1)
    k = rvecs / np.maximum(theta, 1e-12)[:, None]
    kx, ky, kz = k[:, 0], k[:, 1], k[:, 2]
    zero = np.zeros_like(kx)
    kmat = np.stack([zero, -kz, ky, kz, zero, -kx, -ky, kx, zero], axis=1).reshape(-1, 3, 3)
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return np.eye(3)[None] + s * kmat + (1 - c) * kmat @ kmat


def project(K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World points → pixels for one camera (world-to-camera R, t); also the depths."""
    pc = X @ R.T + t
    z = pc[:, 2]
    uv = pc[:, :2] / z[:, None] * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
    return uv, z


def triangulate(K, R1, t1, R2, t2, uv1, uv2) -> np.ndarray:
    P1 = K @ np.hstack([R1, t1[:, None]])
    P2 = K @ np.hstack([R2, t2[:, None]])
    Xh = cv2.triangulatePoints(P1, P2, uv1.T.astype(np.float64), uv2.T.astype(np.float64))
    return (Xh[:3] / Xh[3]).T


def parallax_deg(R1, t1, R2, t2, X) -> np.ndarray:
    c1, c2 = -R1.T @ t1, -R2.T @ t2
    a, b = X - c1, X - c2
    cos = np.sum(a * b, axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1) + 1e-12)
    return np.degrees(np.arccos(np.clip(cos, -1, 1)))


# ---------------------------------------------------------------- state


@dataclass
class Keyframe:
    frame: int
    R: np.ndarray  # world-to-camera
    t: np.ndarray
    obs: dict[int, np.ndarray] = field(default_factory=dict)  # track id → pixel


class _WindowProblem:
    """A window's bundle adjustment as least_squares sees it: the unknowns (a rotation increment and a translation
    per free camera, then the points), the reprojection residuals and their analytic sparse Jacobian."""

    def __init__(self, R0, t0, X0, n_fixed: int, cams, pts_idx, uv, K) -> None:
        self.R0, self.t0, self.n_fixed = R0, t0, n_fixed
        self.n_free, self.n_pts = len(R0) - n_fixed, len(X0)
        self.cams, self.pts_idx, self.uv = cams, pts_idx, uv
        self.fx, self.fy, self.cx, self.cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        n_free, n_obs = self.n_free, len(uv)
        self.x0 = np.concatenate([np.zeros(3 * n_free), t0[n_fixed:].ravel(), X0.ravel()])
        self.fo = fo = np.flatnonzero(cams >= n_fixed)
        cam_col = 6 * (cams[fo] - n_fixed)  # rotation columns, then 3 translation columns after 3*n_free
        pt_col = 6 * n_free + 3 * pts_idx
        # Sparsity pattern (fixed): per observation, 2 rows x (3 point + 6 camera) columns.
        rows_u, rows_v = np.arange(n_obs), n_obs + np.arange(n_obs)
        pr = np.concatenate([np.repeat(rows_u, 3), np.repeat(rows_v, 3)])
        pc_cols = np.concatenate([(pt_col[:, None] + np.arange(3)).ravel()] * 2)
        rot_cols = (cam_col // 2)[:, None] + np.arange(3)  # 3 rotation columns per free camera
        tr_cols = 3 * n_free + (cam_col // 2)[:, None] + np.arange(3)
        cr = np.concatenate([np.repeat(rows_u[fo], 6), np.repeat(rows_v[fo], 6)])
        cc = np.concatenate([np.hstack([rot_cols, tr_cols]).ravel()] * 2)
        self.rows, self.cols = np.concatenate([pr, cr]), np.concatenate([pc_cols, cc])
        self.shape = (2 * n_obs, len(self.x0))

    def unpack(self, x):
        n_free, n_fixed = self.n_free, self.n_fixed
        d = x[: 3 * n_free].reshape(n_free, 3)
        R = self.R0.copy()
        t = self.t0.copy()
        if n_free:
            R[n_fixed:] = rodrigues_batch(d) @ self.R0[n_fixed:]
            t[n_fixed:] = x[3 * n_free : 6 * n_free].reshape(n_free, 3)
        return R, t, x[6 * n_free :].reshape(self.n_pts, 3)

    def camera_frame(self, x):
        R, t, X = self.unpack(x)
        rx = np.einsum("nij,nj->ni", R[self.cams], X[self.pts_idx])
        return R, rx, rx + t[self.cams]

    def residuals(self, x):
        _, _, pc = self.camera_frame(x)
        z = np.maximum(pc[:, 2], 1e-6)
        uv = self.uv
        return np.concatenate(
            [self.fx * pc[:, 0] / z + self.cx - uv[:, 0], self.fy * pc[:, 1] / z + self.cy - uv[:, 1]]
        )

    def jacobian(self, x):
        from scipy.sparse import csr_matrix

        R, rx, pc = self.camera_frame(x)
        fx, fy, fo = self.fx, self.fy, self.fo
        z = np.maximum(pc[:, 2], 1e-6)
        du = np.stack([fx / z, np.zeros_like(z), -fx * pc[:, 0] / z**2], 1)  # d u / d pc
        dv = np.stack([np.zeros_like(z), fy / z, -fy * pc[:, 1] / z**2], 1)
        Rc = R[self.cams]
        ju_p = np.einsum("nj,nji->ni", du, Rc)  # d u / d X = du @ R
        jv_p = np.einsum("nj,nji->ni", dv, Rc)

        # d pc / d rotation increment = -[R X]x ; d pc / d t = I
        def rot(dd):
            return np.cross(rx[fo], dd[fo])  # the row vector d @ (-[a]x) equals a x d

        ju_c = np.hstack([rot(du), du[fo]])
        jv_c = np.hstack([rot(dv), dv[fo]])
        data = np.concatenate([ju_p.ravel(), jv_p.ravel(), ju_c.ravel(), jv_c.ravel()])
        return csr_matrix((data, (self.rows, self.cols)), shape=self.shape)


class VisualOdometry:
    def __init__(self, K: np.ndarray, settings: Settings | None = None):
        self.K = K
        self.s = settings or Settings()
        self.prev_img: np.ndarray | None = None
        self.pts = np.zeros((0, 2), np.float32)  # active tracks' current pixels
        self.tid = np.zeros(0, np.int64)  # active tracks' ids
        self.next_id = 0
        self.points: dict[int, np.ndarray] = {}  # track id → 3-D point (world)
        self.keyframes: list[Keyframe] = []
        self.poses: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # frame → (R_cw, t_cw)
        self.initialised = False
        self.lost = False
        self.init_ref: int | None = None
        self.buffer: list[tuple[int, np.ndarray, np.ndarray]] = []  # frames waiting for init: (frame, tid, pts)
        self.ref_pts: dict[int, np.ndarray] = {}
        self.kf_pts_at_creation = 0
        self.last_kf_pts: dict[int, np.ndarray] = {}

    # ------------------------------------------------------------ frame loop
    def process(self, frame: int, img: np.ndarray) -> None:
        if self.lost:
            return
        if self.prev_img is None:
            self._start_init(frame, img)
            self.prev_img = img
            return
        self._track(img)
        self.prev_img = img
        if not self.initialised:
            self._try_init(frame, img)
        else:
            self._locate(frame, img)

    def _detect(self, img: np.ndarray, n: int) -> np.ndarray:
        mask = np.full(img.shape, 255, np.uint8)
        for x, y in self.pts.astype(int):
            cv2.circle(mask, (int(x), int(y)), self.s.min_corner_distance, 0, -1)
        corners = cv2.goodFeaturesToTrack(img, n, self.s.quality_level, self.s.min_corner_distance, mask=mask)
        return np.zeros((0, 2), np.float32) if corners is None else corners.reshape(-1, 2).astype(np.float32)

    def _add_tracks(self, new_pts: np.ndarray) -> np.ndarray:
        ids = np.arange(self.next_id, self.next_id + len(new_pts))
        self.next_id += len(new_pts)
        self.pts = np.vstack([self.pts, new_pts]).astype(np.float32)
        self.tid = np.concatenate([self.tid, ids])
        return ids

    def _track(self, img: np.ndarray) -> None:
        if len(self.pts) == 0:
            return
        lk = dict(
            winSize=(self.s.klt_window, self.s.klt_window),
            maxLevel=self.s.klt_levels,
            criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01),
        )
        p1, st1, _ = cv2.calcOpticalFlowPyrLK(self.prev_img, img, self.pts, None, **lk)
        p0, st0, _ = cv2.calcOpticalFlowPyrLK(img, self.prev_img, p1, None, **lk)
        fb = np.linalg.norm(p0 - self.pts, axis=1)
        h, w = img.shape
        ok = (st1[:, 0] == 1) & (st0[:, 0] == 1) & (fb < self.s.fb_max_error_px)
        ok &= (p1[:, 0] >= 0) & (p1[:, 0] < w - 1) & (p1[:, 1] >= 0) & (p1[:, 1] < h - 1)
        self.pts, self.tid = p1[ok], self.tid[ok]

    # ------------------------------------------------------------ initialisation
    def _start_init(self, frame: int, img: np.ndarray) -> None:
        self.pts = np.zeros((0, 2), np.float32)
        self.tid = np.zeros(0, np.int64)
        self._add_tracks(self._detect(img, self.s.max_corners))
        self.init_ref = frame
        self.ref_pts = dict(zip(self.tid.tolist(), self.pts.copy(), strict=True))
        self.buffer = [(frame, self.tid.copy(), self.pts.copy())]

    def _try_init(self, frame: int, img: np.ndarray) -> None:
        self.buffer.append((frame, self.tid.copy(), self.pts.copy()))
        if frame - self.init_ref > self.s.init_max_frames or len(self.pts) < self.s.init_min_inliers:
            log(f"frame {frame}: initialisation restarted (not enough parallax or tracks since frame {self.init_ref})")
            self._start_init(frame, img)
            return
        ref = np.array([self.ref_pts[i] for i in self.tid.tolist()])
        if np.median(np.linalg.norm(self.pts - ref, axis=1)) < self.s.init_min_parallax_px:
            return
        E, mask = cv2.findEssentialMat(ref, self.pts, self.K, cv2.RANSAC, 0.999, 1.0)
        if E is None or E.shape != (3, 3):
            return
        n_in, R, t, mask = cv2.recoverPose(E, ref, self.pts, self.K, mask=mask)
        inl = mask.ravel() > 0
        if n_in < self.s.init_min_inliers:
            return
        R0, t0 = np.eye(3), np.zeros(3)
        t = t.ravel()
        X = triangulate(self.K, R0, t0, R, t, ref[inl], self.pts[inl])
        ang = parallax_deg(R0, t0, R, t, X)
        z0 = X[:, 2]
        z1 = (X @ R.T + t)[:, 2]
        good = (z0 > 0) & (z1 > 0) & (ang > 0.2)
        if good.sum() < self.s.init_min_inliers or np.median(ang[good]) < self.s.init_min_angle_deg:
            return
        scale = 1.0 / np.median(z0[good])  # median depth of the first map = 1
        X *= scale
        t = t * scale
        ids = self.tid[inl][good]
        for i, x in zip(ids.tolist(), X[good], strict=True):
            self.points[i] = x
        kf0 = Keyframe(self.init_ref, R0, t0, {i: self.ref_pts[i] for i in ids.tolist()})
        kf1 = Keyframe(frame, R, t, dict(zip(self.tid.tolist(), self.pts.copy(), strict=True)))
        self.keyframes = [kf0, kf1]
        self.initialised = True
        log(
            f"frame {frame}: initialised from frames {self.init_ref}-{frame} with {len(ids)} points, "
            f"median parallax {np.median(ang[good]):.2f} deg"
        )
        self._bundle_adjust()
        # Place the frames seen while initialising.
        for f, tids, pts in self.buffer:
            if f == frame or f == self.init_ref:
                continue
            pose = self._pnp(tids, pts, self.keyframes[-1].R, self.keyframes[-1].t)
            if pose is not None:
                self.poses[f] = pose[:2]
        self.poses[self.init_ref] = (kf0.R, kf0.t)
        self.poses[frame] = (self.keyframes[1].R, self.keyframes[1].t)
        self.buffer = []
        self._new_keyframe_features(img, self.keyframes[1])
        self.last_kf_pts = dict(zip(self.tid.tolist(), self.pts.copy(), strict=True))
        self.kf_pts_at_creation = self._n_map_tracks()

    # ------------------------------------------------------------ tracking
    def _n_map_tracks(self) -> int:
        return sum(1 for i in self.tid.tolist() if i in self.points)

    def _pnp(self, tids, pts, R_guess, t_guess):
        """Pose of a frame from its tracked map points: RANSAC, then least squares on the inliers.

        Candidates (guess-seeded RANSAC, guess-free EPnP RANSAC, each refined or not) are judged by our
        own reprojection test, so no solver's corner case can slip a wrong pose through.
        """
        has = np.array([i in self.points for i in tids.tolist()], bool)
        if has.sum() < self.s.min_tracked_points:
            return None
        X = np.array([self.points[i] for i in tids[has].tolist()])
        uv = pts[has].astype(np.float64)
        thr = self.s.pnp_reprojection_px
        rvec0, _ = cv2.Rodrigues(R_guess)
        candidates = []
        for guess, flags in ((True, cv2.SOLVEPNP_ITERATIVE), (False, cv2.SOLVEPNP_EPNP)):
            ok, rvec, tvec, inliers = cv2.solvePnPRansac(
                X, uv, self.K, None, rvec0.copy(), t_guess.reshape(3, 1).copy(), useExtrinsicGuess=guess,
                iterationsCount=100, reprojectionError=thr, confidence=0.999, flags=flags,
            )  # fmt: skip
            if not ok or inliers is None or len(inliers) < self.s.min_tracked_points:
                continue
            candidates.append((rvec, tvec))
            inl = inliers.ravel()
            refined = cv2.solvePnPRefineLM(X[inl], uv[inl], self.K, None, rvec.copy(), tvec.copy())
            candidates.append(refined)
            if len(candidates) >= 2 and self._count_inliers(X, uv, *refined, thr) >= 0.5 * len(X):
                break  # a good pose from the guess: no need for the guess-free search
        best, best_n = None, 0
        for rvec, tvec in candidates:
            n = self._count_inliers(X, uv, rvec, tvec, thr)
            if n > best_n:
                best, best_n = (rvec, tvec), n
        if best is None or best_n < self.s.min_tracked_points:
            return None
        R, _ = cv2.Rodrigues(best[0])
        t = best[1].ravel()
        proj, z = project(self.K, R, t, X)
        good = (np.linalg.norm(proj - uv, axis=1) < thr) & (z > 0)
        outlier_ids = set(tids[has][~good].tolist())
        return R, t, outlier_ids

    def _count_inliers(self, X, uv, rvec, tvec, thr) -> int:
        R, _ = cv2.Rodrigues(rvec)
        proj, z = project(self.K, R, np.asarray(tvec).ravel(), X)
        if not np.isfinite(proj).all():
            return 0
        return int(np.count_nonzero((np.linalg.norm(proj - uv, axis=1) < thr) & (z > 0)))

    def _locate(self, frame: int, img: np.ndarray) -> None:
        R_prev, t_prev = self.poses[max(self.poses)]
        res = self._pnp(self.tid, self.pts, R_prev, t_prev)
        if res is None:
            self.lost = True
            log(f"LOST at frame {frame}: fewer than {self.s.min_tracked_points} map points could place the frame")
            return
        R, t, outliers = res
        if outliers:
            keep = np.array([i not in outliers for i in self.tid.tolist()], bool)
            self.pts, self.tid = self.pts[keep], self.tid[keep]
        self.poses[frame] = (R, t)
        if self._need_keyframe(frame):
            kf = Keyframe(frame, R, t, dict(zip(self.tid.tolist(), self.pts.copy(), strict=True)))
            self.keyframes.append(kf)
            self._triangulate_new(kf)
            self._bundle_adjust()
            self.poses[frame] = (kf.R, kf.t)
            self._new_keyframe_features(img, kf)
            self.last_kf_pts = dict(zip(self.tid.tolist(), self.pts.copy(), strict=True))
            self.kf_pts_at_creation = self._n_map_tracks()

    def _need_keyframe(self, frame: int) -> bool:
        since = frame - self.keyframes[-1].frame
        n_map = self._n_map_tracks()
        common = [i for i in self.tid.tolist() if i in self.last_kf_pts]
        if common:
            cur = dict(zip(self.tid.tolist(), self.pts, strict=True))
            par = np.median([np.linalg.norm(cur[i] - self.last_kf_pts[i]) for i in common])
        else:
            par = np.inf
        if since < 2:
            return False
        return (
            since >= self.s.kf_max_frames
            or par > self.s.kf_min_parallax_px
            or n_map < self.s.kf_min_point_ratio * self.kf_pts_at_creation
        )

    def _triangulate_new(self, kf: Keyframe) -> None:
        """Points for tracks seen in an earlier keyframe and now, with enough parallax."""
        Kinv_ok = 0
        for old in self.keyframes[-4:-1][::-1]:
            ids = [i for i in kf.obs if i not in self.points and i in old.obs]
            if not ids:
                continue
            uv1 = np.array([old.obs[i] for i in ids])
            uv2 = np.array([kf.obs[i] for i in ids])
            X = triangulate(self.K, old.R, old.t, kf.R, kf.t, uv1, uv2)
            ang = parallax_deg(old.R, old.t, kf.R, kf.t, X)
            e1, z1 = project(self.K, old.R, old.t, X)
            e2, z2 = project(self.K, kf.R, kf.t, X)
            err = np.maximum(np.linalg.norm(e1 - uv1, axis=1), np.linalg.norm(e2 - uv2, axis=1))
            good = (z1 > 0) & (z2 > 0) & (ang > self.s.triangulation_min_angle_deg) & (err < 2.0)
            for i, x in zip(np.array(ids)[good].tolist(), X[good], strict=True):
                self.points[i] = x
                Kinv_ok += 1

    def _new_keyframe_features(self, img: np.ndarray, kf: Keyframe) -> None:
        n_missing = self.s.max_corners - len(self.pts)
        if n_missing > 20:
            new = self._detect(img, n_missing)
            ids = self._add_tracks(new)
            for i, p in zip(ids.tolist(), new, strict=True):
                kf.obs[i] = p

    # ------------------------------------------------------------ bundle adjustment
    def _bundle_adjust(self) -> None:
        """Windowed bundle adjustment over the last keyframes; the window's first two stay fixed (gauge and scale).

        Cameras move by a left rotation increment exp(d) R0 and a translation; analytic sparse Jacobian.
        """
        window = self.keyframes[-self.s.ba_window :]
        n_fixed = min(2, len(window))
        counts: dict[int, int] = {}
        for kf in window:
            for i in kf.obs:
                if i in self.points:
                    counts[i] = counts.get(i, 0) + 1
        pids = [i for i, c in counts.items() if c >= 2]
        if not pids:
            return
        pindex = {p: j for j, p in enumerate(pids)}
        cams, pts_idx, uv = [], [], []
        for ci, kf in enumerate(window):
            for i, p in kf.obs.items():
                if i in pindex:
                    cams.append(ci)
                    pts_idx.append(pindex[i])
                    uv.append(p)
        cams, pts_idx, uv = np.array(cams), np.array(pts_idx), np.array(uv, float)
        R0 = np.array([kf.R for kf in window])
        t0 = np.array([kf.t for kf in window])
        X0 = np.array([self.points[p] for p in pids])
        ba = _WindowProblem(R0, t0, X0, n_fixed, cams, pts_idx, uv, self.K)
        r0 = ba.residuals(ba.x0)
        sol = least_squares(
            ba.residuals,
            ba.x0,
            jac=ba.jacobian,
            loss="huber",
            f_scale=1.5,
            x_scale="jac",
            max_nfev=self.s.ba_max_evaluations,
            method="trf",
        )
        before = np.abs(r0.reshape(2, -1)).max(axis=0)
        after = np.abs(sol.fun.reshape(2, -1)).max(axis=0)
        if not np.isfinite(sol.x).all() or np.median(after) > max(np.median(before), 0.5) * 1.5:
            # The optimisation went astray: keep the map as it was, drop only what was bad before.
            for p in set(np.array(pids)[pts_idx[before > 4.0]].tolist()):
                self.points.pop(p, None)
            return
        R, t, X = ba.unpack(sol.x)
        for ci in range(n_fixed, len(window)):
            window[ci].R, window[ci].t = R[ci], t[ci]
            self.poses[window[ci].frame] = (R[ci], t[ci])
        for j, p in enumerate(pids):
            self.points[p] = X[j]
        # Drop points with a large reprojection error in any window keyframe.
        for p in set(np.array(pids)[pts_idx[after > 4.0]].tolist()):
            self.points.pop(p, None)

    # ------------------------------------------------------------ results
    def trajectory(self) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """(frame, camera-to-world rotation, camera position) of every placed frame, in frame order."""
        out = []
        for f in sorted(self.poses):
            R, t = self.poses[f]
            out.append((f, R.T, -R.T @ t))
        return out


def rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    """qx qy qz qw with qw >= 0 (Shepperd's method; the runner re-normalises on reading)."""
    tr = np.trace(R)
    if tr > 0:
        s = np.sqrt(tr + 1.0) * 2
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        q = [0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s]
    elif R[1, 1] > R[2, 2]:
        s = np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        q = [(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s]
    else:
        s = np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        q = [(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s]
    q = np.array(q)
    return q if q[3] >= 0 else -q


if __name__ == "__main__":  # pragma: no cover
    sys.exit("run it as: python -m slamrun.methods.reference_vo --help")
