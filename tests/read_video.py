"""Reads a video back with PyAV (FFmpeg's decoders), independently of dextrain's encoder.

Usage: python3 tests/read_video.py VIDEO [PROBES]
PROBES: JSON list of [frame, x, y]: the decoded RGB pixel at column x, row y of that frame.
Prints one JSON line: codec, width, height, frames (decoded), duration (s, from the stream),
fps (the stream's average rate) and probes ([r, g, b] per probe).
"""

import json
import sys

import av


def main():
    path = sys.argv[1]
    probes = json.loads(sys.argv[2]) if len(sys.argv) > 2 else []
    wanted = {}
    for i, (f, x, y) in enumerate(probes):
        wanted.setdefault(int(f), []).append((i, int(x), int(y)))
    out = [None] * len(probes)
    with av.open(path) as container:
        stream = container.streams.video[0]
        frames = 0
        for frame in container.decode(stream):
            if frames in wanted:
                rgb = frame.to_ndarray(format="rgb24")
                for i, x, y in wanted[frames]:
                    out[i] = [int(v) for v in rgb[y, x]]
            frames += 1
        duration = float(stream.duration * stream.time_base) if stream.duration is not None else None
        print(json.dumps({
            "codec": stream.codec_context.name,
            "width": stream.codec_context.width,
            "height": stream.codec_context.height,
            "frames": frames,
            "duration": duration,
            "fps": float(stream.average_rate) if stream.average_rate else None,
            "probes": out,
        }))


if __name__ == "__main__":
    main()
