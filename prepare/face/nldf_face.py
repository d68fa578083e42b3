"""nldf's face helper: mediapipe's face landmarker and selfie segmentation over a folder of
frames, run by `nldf prepare` in its own Python environment (mediapipe 0.10.21, whose wheel
carries the models). Also extracts mediapipe's canonical face from the npm package
@mediapipe/face_mesh at install time.

Commands:
  frames --frames DIR --count N --out DIR
      reads DIR/<i>.jpg for i in 0..N and writes into --out:
        landmarks.f32  N x 468 x 3 little-endian float32: x, y in pixels, z in pixels
                       (mediapipe's relative depth); NaN where no face was found
        faces.u8       N bytes: faces the landmarker found (0, 1 or 2)
        detections.u8  N bytes: faces the detector found on every 5th frame, 255 elsewhere
        mask/<i>.png   the person's probability, 0-255, the frame's size
        tracks.f32     M x 4 little-endian float32 rows (frame, track id, x, y), pixels,
                       ordered by frame, then track: corner features on the rigid part of
                       the head (forehead, hair, nose, cheeks; not the eyes, the lips or
                       the chin) followed by pyramidal Lucas-Kanade with a forward-backward
                       check, forward and (frames of 256 pixels and up) back in time from
                       the frame each was found in
      prints "done <i>" after each frame.
  canonical --assets FILE --loader FILE --out FILE
      decodes the canonical face (468 vertices, cm) and the rigid landmarks' weights from
      the npm package's packed assets and writes them as JSON.
"""

import argparse
import collections
import json
import os
import re
import struct
import sys

# mediapipe face mesh indices: the lips, the eyes (with their lids), the face's oval, and the
# forehead's top (10), the upper lip's top (0) and the chin (152).
LIPS = [0, 13, 14, 17, 37, 39, 40, 61, 78, 80, 81, 82, 84, 87, 88, 91, 95, 146, 178, 181,
        185, 191, 267, 269, 270, 291, 308, 310, 311, 312, 314, 317, 318, 321, 324, 375, 402,
        405, 409, 415]
LEFT_EYE = [249, 263, 362, 373, 374, 380, 381, 382, 384, 385, 386, 387, 388, 390, 398, 466]
RIGHT_EYE = [7, 33, 133, 144, 145, 153, 154, 155, 157, 158, 159, 160, 161, 163, 173, 246]
FOREHEAD, UPPER_LIP, CHIN = 10, 0, 152


class Tracker:
    """Corner features on the rigid part of the head, tracked frame to frame.

    The region: the hull of the 468 landmarks grown upward by `reach` times the face's
    height (0 keeps the face's own outline, the forehead up to the hairline; hair slides and
    sways, and its tracks turn the head too little), inside the person mask shrunk away from the silhouette (whose
    points slide over the surface), less the eyes' and the lips' hulls grown by a margin and
    everything below the upper lip (the jaw moves with the mouth). Tracks follow by
    pyramidal Lucas-Kanade from the previous frame, kept when tracking back lands within
    `fb_px` of where they started; then each is aligned with its patch in the frame it was
    found in, turned as the patches found with it have turned since (a rolling head turns
    them), starting from there, so that it does not drift, and kept when that moves it
    by less than `anchor_px` and it stays in the region. Corners stronger than `quality`
    times the region's strongest (Shi-Tomasi) top the live tracks up to `most` when fewer
    than `least` are alive, at most every `detect_every` frames; each new corner is also
    followed back in time, with the same checks, through up to `back_frames` earlier
    frames, so that a frame sees the points found after it too (without this, a clip's
    first frames saw a quarter of the tracks its later frames did, and every track was
    shorter).

    Frames of at least 256 pixels take weaker corners (`quality` 0.01, not 0.045) and follow
    them back 90 frames; smaller ones neither: on the tuning videos (seeds 0-2, both heads)
    that posed the 512 videos better and the 128 videos worse (docs/prepare.md).
    """

    def __init__(self, size, reach):
        import cv2
        import numpy as np
        self.cv2 = cv2
        self.reach = reach
        self.scale = size / 512.0
        self.least, self.most = 150, 300
        self.min_distance = max(3, int(round(8 * self.scale)))
        win = max(9, int(round(21 * self.scale)) | 1)
        self.lk = dict(winSize=(win, win), maxLevel=3 if size >= 256 else 2,
                       criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))
        self.fb_px = max(0.25, 0.5 * self.scale)
        self.margin = max(2, int(round(10 * self.scale)))
        fine = size >= 256
        self.quality = 0.01 if fine else 0.045
        self.block = max(3, int(round(7 * self.scale)) | 1)
        self.anchor_px = max(0.25, self.scale)
        self.prev = None
        self.points = np.zeros((0, 2), np.float32)
        self.ids = np.zeros(0, np.int64)
        self.births = np.zeros(0, np.int64)
        self.anchors = np.zeros((0, 2), np.float32)
        self.templates = {}
        self.next_id = 0
        self.detect_every = 3
        self.last_detect = -self.detect_every
        self.back_frames = 90 if fine else 0
        # (frame, gray, region) of the last `back_frames` frames, oldest first.
        self.history = collections.deque(maxlen=self.back_frames)
        self.rows = []

    def region(self, pts, person):
        import numpy as np
        cv2 = self.cv2
        h, w = person.shape
        up = pts[FOREHEAD] - pts[CHIN]
        grown = np.concatenate([pts, pts + self.reach * up])
        mask = np.zeros((h, w), np.uint8)
        cv2.fillConvexPoly(mask, cv2.convexHull(grown.astype(np.int32)), 255)
        inside = (person > 127).astype(np.uint8) * 255
        k = 2 * self.margin + 1
        mask &= cv2.erode(inside, np.ones((k, k), np.uint8))
        # Below the upper lip: the side of the line through it, across the face, that the
        # chin is on.
        across = np.array([up[1], -up[0]])
        lip = pts[UPPER_LIP] - 0.05 * up
        far = 4.0 * (abs(up[0]) + abs(up[1]) + w + h)
        lower = np.array([lip - far * across / (np.linalg.norm(across) + 1e-9),
                          lip + far * across / (np.linalg.norm(across) + 1e-9)])
        lower = np.concatenate([lower, lower[::-1] - far * up / (np.linalg.norm(up) + 1e-9)])
        cv2.fillConvexPoly(mask, lower.astype(np.int32), 0)
        for part in (LIPS, LEFT_EYE, RIGHT_EYE):
            hull = cv2.convexHull(pts[part].astype(np.int32))
            cv2.fillConvexPoly(mask, hull, 0)
            cv2.polylines(mask, [hull], True, 0, thickness=2 * self.margin)
        return mask

    def step(self, i, gray, pts, person):
        """Tracks into frame `i` (its landmarks `pts`, 468 x 2, or None) and records it."""
        mask = self.region(pts, person) if pts is not None else None
        if self.prev is not None and len(self.points):
            good, p1 = self.follow(gray, mask)
            self.points, self.ids = p1[good], self.ids[good]
            self.births, self.anchors = self.births[good], self.anchors[good]
            alive = set(self.births.tolist())
            self.templates = {b: t for b, t in self.templates.items() if b in alive}
        due = i - self.last_detect >= self.detect_every
        if mask is not None and len(self.points) < self.least and due:
            self.detect(i, gray, mask)
            self.last_detect = i
        self.prev = gray
        self.history.append((i, gray, mask))
        for (x, y), t in zip(self.points, self.ids):
            self.rows.append((i, t, x, y))

    def follow(self, gray, mask):
        """Frame-to-frame flow checked forward-backward, then each track aligned with its
        first frame's patch from there (so it does not drift): which tracks survive, and
        where they are."""
        import numpy as np
        good, p1 = self.flow(self.prev, gray, self.points)
        for b in np.unique(self.births):
            sel = np.flatnonzero((self.births == b) & good)
            if len(sel):
                self.anchor(self.templates[b], self.anchors[sel], gray, p1, good, sel)
        if mask is None:
            good[:] = False
        else:
            good &= self.inside(p1, mask)
        return good, p1

    def flow(self, a, b, pts):
        """Pyramidal Lucas-Kanade of `pts` from image `a` into `b`, kept where flowing back
        lands within `fb_px` of the start: which points survive, and where they are in `b`."""
        import numpy as np
        cv2 = self.cv2
        p0 = pts.reshape(-1, 1, 2)
        p1, ok1, _ = cv2.calcOpticalFlowPyrLK(a, b, p0, None, **self.lk)
        back, ok2, _ = cv2.calcOpticalFlowPyrLK(b, a, p1, None, **self.lk)
        fb = np.linalg.norm((back - p0).reshape(-1, 2), axis=1)
        good = (ok1.ravel() == 1) & (ok2.ravel() == 1) & (fb < self.fb_px)
        return good, p1.reshape(-1, 2).copy()

    def inside(self, pts, mask):
        """Which of `pts` are finite and fall in the tracking region `mask`."""
        import numpy as np
        xi = np.clip(np.round(pts[:, 0]).astype(int), 0, mask.shape[1] - 1)
        yi = np.clip(np.round(pts[:, 1]).astype(int), 0, mask.shape[0] - 1)
        return np.isfinite(pts).all(axis=1) & (mask[yi, xi] > 0)

    def anchor(self, template, anchors, gray, pts, good, sel):
        """Aligns the points `pts[sel]` in `gray` with their patches at `anchors` in
        `template` (`align`), in place: a point that moves `anchor_px` or more, or fails to
        align, leaves `good`."""
        import numpy as np
        got, ok = self.align(template, anchors, gray, pts[sel])
        good[sel] &= ok & (np.linalg.norm(got - pts[sel], axis=1) < self.anchor_px)
        pts[sel] = got

    def turn(self, anchors, guess):
        """The 2D rotation and shift (2 x 3) that best take `anchors` onto `guess` in least
        squares (the shift alone for fewer than three points): how far the patches turned
        in the image since they were found, as a head that rolls turns them."""
        import numpy as np
        m = np.eye(2, 3, dtype=np.float64)
        if len(anchors) >= 3:
            a = anchors - anchors.mean(axis=0)
            b = guess - guess.mean(axis=0)
            angle = np.arctan2((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum(), (a * b).sum())
            m[:, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
        m[:, 2] = guess.mean(axis=0) - m[:, :2] @ anchors.mean(axis=0)
        return m

    def align(self, template, anchors, gray, guess):
        """Lucas-Kanade of the patches at `anchors` in `template` onto `gray`, from `guess`,
        on crops around the points (the guess is close: no pyramid is needed)."""
        import numpy as np
        cv2 = self.cv2
        m = self.lk["winSize"][0] + 2
        full = np.array(gray.shape[::-1])
        spread = np.maximum(np.ptp(anchors, axis=0), np.ptp(guess, axis=0))
        size = np.minimum(np.ceil(spread).astype(int) + 2 * m + 1, full)

        def crop(img, pts):
            # The same size in both images, as Lucas-Kanade needs.
            lo = np.floor(pts.min(axis=0) - m).astype(int)
            lo = np.clip(lo, 0, full - size)
            return img[lo[1]:lo[1] + size[1], lo[0]:lo[0] + size[0]], lo.astype(np.float32)

        g_img, g_lo = crop(gray, guess)
        # The template turned as the patches have turned since, into the crop's frame: a
        # patch compared unturned pulls its point back towards where it was found (a head
        # rolled 12 degrees: its tracks turned 7 % short, and a real face's pose turned
        # sideways with the roll; docs/prepare.md, "Tracks aligned turned").
        warp = self.turn(anchors.astype(np.float64), guess.astype(np.float64))
        warp[:, 2] -= g_lo
        t_img = cv2.warpAffine(template, warp, (g_img.shape[1], g_img.shape[0]),
                               flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        start = anchors @ warp[:, :2].T + warp[:, 2]
        got, ok, _ = cv2.calcOpticalFlowPyrLK(
            t_img, g_img, start.reshape(-1, 1, 2).astype(np.float32),
            (guess - g_lo).reshape(-1, 1, 2).copy(), winSize=self.lk["winSize"], maxLevel=0,
            criteria=self.lk["criteria"], flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
        return got.reshape(-1, 2) + g_lo, ok.ravel() == 1

    def detect(self, i, gray, mask):
        """New corners in the region of frame `i`, away from the live tracks."""
        import numpy as np
        cv2 = self.cv2
        free = mask.copy()
        for x, y in self.points:
            cv2.circle(free, (int(round(x)), int(round(y))), self.min_distance, 0, -1)
        wanted = self.most - len(self.points)
        ys, xs = np.nonzero(free)
        if wanted <= 0 or not len(xs):
            return
        x0, y0, x1, y1 = xs.min(), ys.min(), xs.max() + 1, ys.max() + 1
        found = cv2.goodFeaturesToTrack(gray[y0:y1, x0:x1], wanted, self.quality,
                                        self.min_distance, mask=free[y0:y1, x0:x1],
                                        blockSize=self.block)
        if found is None:
            return
        found = found.reshape(-1, 2).astype(np.float32) + np.array([x0, y0], np.float32)
        ids = np.arange(self.next_id, self.next_id + len(found))
        self.next_id += len(found)
        self.points = np.concatenate([self.points, found]).astype(np.float32)
        self.ids = np.concatenate([self.ids, ids])
        self.births = np.concatenate([self.births, np.full(len(found), i)])
        self.anchors = np.concatenate([self.anchors, found]).astype(np.float32)
        self.templates[i] = gray
        self.extend_back(gray, found, ids)

    def extend_back(self, gray, found, ids):
        """Follows corners just found back through the frames kept in `history`, so that
        the frames before a detection see the points it found."""
        import numpy as np
        later, pts, anchors, alive = gray, found.copy(), found.copy(), ids.copy()
        for j, g, m in reversed(self.history):
            if m is None or not len(alive):
                break
            good, p1 = self.flow(later, g, pts)
            sel = np.flatnonzero(good)
            if len(sel):
                self.anchor(gray, anchors[sel], g, p1, good, sel)
            good &= self.inside(p1, m)
            pts, anchors, alive = p1[good], anchors[good], alive[good]
            for (x, y), t in zip(pts, alive):
                self.rows.append((j, t, x, y))
            later = g

    def save(self, path):
        import numpy as np
        rows = np.asarray(self.rows, dtype="<f4").reshape(-1, 4)
        rows[np.lexsort((rows[:, 1], rows[:, 0]))].tofile(path)


def run_frames(args):
    import cv2
    import mediapipe as mp
    import numpy as np

    os.makedirs(os.path.join(args.out, "mask"), exist_ok=True)
    mesh = mp.solutions.face_mesh.FaceMesh(
        static_image_mode=False, max_num_faces=2, refine_landmarks=False,
        min_detection_confidence=0.5, min_tracking_confidence=0.5)
    detector = mp.solutions.face_detection.FaceDetection(
        model_selection=1, min_detection_confidence=0.6)
    segmenter = mp.solutions.selfie_segmentation.SelfieSegmentation(model_selection=0)
    n = args.count
    landmarks = np.full((n, 468, 3), np.nan, dtype="<f4")
    faces = np.zeros(n, dtype=np.uint8)
    detections = np.full(n, 255, dtype=np.uint8)
    tracker = None
    for i in range(n):
        path = os.path.join(args.frames, "%d.jpg" % i)
        bgr = cv2.imread(path)
        if bgr is None:
            print("error %s: cannot read the frame" % path, file=sys.stderr)
            return 2
        h, w = bgr.shape[:2]
        rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        found = mesh.process(rgb).multi_face_landmarks or []
        faces[i] = len(found)
        if found:
            pts = found[0].landmark
            landmarks[i] = [(p.x * w, p.y * h, p.z * w) for p in pts[:468]]
        if i % 5 == 0:
            d = detector.process(rgb).detections or []
            detections[i] = min(len(d), 254)
        prob = segmenter.process(rgb).segmentation_mask
        mask = np.clip(prob * 255.0 + 0.5, 0, 255).astype(np.uint8)
        cv2.imwrite(os.path.join(args.out, "mask", "%d.png" % i), mask)
        if tracker is None:
            tracker = Tracker(min(h, w), args.track_reach)
        one = landmarks[i, :, :2] if faces[i] == 1 else None
        tracker.step(i, cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY), one, mask)
        print("done %d" % i, flush=True)
    landmarks.tofile(os.path.join(args.out, "landmarks.f32"))
    faces.tofile(os.path.join(args.out, "faces.u8"))
    detections.tofile(os.path.join(args.out, "detections.u8"))
    if tracker is not None:
        tracker.save(os.path.join(args.out, "tracks.f32"))
    else:
        np.zeros((0, 4), dtype="<f4").tofile(os.path.join(args.out, "tracks.f32"))
    return 0


def _varint(b, i):
    r = s = 0
    while True:
        c = b[i]
        i += 1
        r |= (c & 0x7F) << s
        s += 7
        if c < 0x80:
            return r, i


def _fields(b):
    """(field number, wire type, value) of a protobuf message's bytes."""
    i = 0
    while i < len(b):
        key, i = _varint(b, i)
        field, wire = key >> 3, key & 7
        if wire == 0:
            v, i = _varint(b, i)
        elif wire == 2:
            n, i = _varint(b, i)
            v = b[i:i + n]
            i += n
        elif wire == 5:
            v = b[i:i + 4]
            i += 4
        elif wire == 1:
            v = b[i:i + 8]
            i += 8
        else:
            raise ValueError("unknown wire type %d" % wire)
        yield field, wire, v


def _floats(fields, number):
    out = []
    for f, w, v in fields:
        if f != number:
            continue
        if w == 5:
            out.append(struct.unpack("<f", v)[0])
        elif w == 2:
            out.extend(struct.unpack("<%df" % (len(v) // 4), v))
    return out


def run_canonical(args):
    loader = open(args.loader, encoding="utf-8").read()
    name = "geometry_pipeline_metadata_landmarks.binarypb"
    m = re.search(r'"filename":\s*"[^"]*' + re.escape(name) + r'",\s*"start":\s*(\d+),\s*"end":\s*(\d+)', loader)
    if not m:
        print("error %s: no %s in the package's asset list" % (args.loader, name), file=sys.stderr)
        return 2
    start, end = int(m.group(1)), int(m.group(2))
    blob = open(args.assets, "rb").read()[start:end]
    top = list(_fields(blob))
    mesh = [v for f, w, v in top if f == 1 and w == 2]
    if not mesh:
        print("error %s: no canonical mesh in %s" % (args.assets, name), file=sys.stderr)
        return 2
    buf = _floats(list(_fields(mesh[0])), 3)
    if len(buf) != 468 * 5:
        print("error %s: the canonical mesh has %d floats, not 468 x 5" % (args.assets, len(buf)), file=sys.stderr)
        return 2
    vertices = [buf[5 * k:5 * k + 3] for k in range(468)]
    weights = [0.0] * 468
    for f, w, v in top:
        if f == 2 and w == 2:
            ref = dict((ff, vv) for ff, _, vv in _fields(v))
            weight = struct.unpack("<f", ref[2])[0] if 2 in ref else 0.0
            weights[ref.get(1, 0)] = weight
    out = {
        "source": "npm @mediapipe/face_mesh, " + name + " (Apache-2.0)",
        "units": "cm",
        "vertices": vertices,
        "rigid_weights": weights,
    }
    tmp = args.out + ".part"
    with open(tmp, "w", encoding="utf-8") as fh:
        json.dump(out, fh)
    os.replace(tmp, args.out)
    return 0


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    f = sub.add_parser("frames")
    f.add_argument("--frames", required=True)
    f.add_argument("--count", type=int, required=True)
    f.add_argument("--out", required=True)
    f.add_argument("--track-reach", type=float, required=True)
    c = sub.add_parser("canonical")
    c.add_argument("--assets", required=True)
    c.add_argument("--loader", required=True)
    c.add_argument("--out", required=True)
    args = p.parse_args()
    return run_frames(args) if args.command == "frames" else run_canonical(args)


if __name__ == "__main__":
    sys.exit(main())
