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
      prints "done <i>" after each frame.
  canonical --assets FILE --loader FILE --out FILE
      decodes the canonical face (468 vertices, cm) and the rigid landmarks' weights from
      the npm package's packed assets and writes them as JSON.
"""

import argparse
import json
import os
import re
import struct
import sys


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
        print("done %d" % i, flush=True)
    landmarks.tofile(os.path.join(args.out, "landmarks.f32"))
    faces.tofile(os.path.join(args.out, "faces.u8"))
    detections.tofile(os.path.join(args.out, "detections.u8"))
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
    c = sub.add_parser("canonical")
    c.add_argument("--assets", required=True)
    c.add_argument("--loader", required=True)
    c.add_argument("--out", required=True)
    args = p.parse_args()
    return run_frames(args) if args.command == "frames" else run_canonical(args)


if __name__ == "__main__":
    sys.exit(main())
