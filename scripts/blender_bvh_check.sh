#!/usr/bin/env bash
# Opens a BVH file with Blender's own importer (headless) and checks what Blender sees.
#
# Usage:
#   scripts/blender_bvh_check.sh FILE.bvh [JOINTS FRAMES FPS]
#
# Prints the joint (bone) count, frame count and frame rate as Blender imports them. With the
# expected values given, exits 1 on any mismatch (FPS within 0.001), 2 if Blender cannot
# import the file or is missing. Needs Blender (Debian: `apt-get install -y blender`; tested
# with 3.4.1); set BLENDER to use another binary. Takes about 2 s plus Blender's start-up.
#
# To check our exporter: `cargo test -p model --lib bvh::tests::writes_a_sample_export` writes
# $TMPDIR/danced-export-sample.bvh (22 joints, 90 frames, 30 fps), then
#   scripts/blender_bvh_check.sh /tmp/danced-export-sample.bvh 22 90 30
#
# Not part of the test suite: the tests do not need Blender.
set -euo pipefail

if [[ $# -ne 1 && $# -ne 4 ]]; then
    echo "usage: $0 FILE.bvh [JOINTS FRAMES FPS]" >&2
    exit 2
fi
file=$1
if [[ ! -r $file ]]; then
    echo "$file: not readable" >&2
    exit 2
fi
blender=${BLENDER:-blender}
if ! command -v "$blender" >/dev/null; then
    echo "$blender not found (apt-get install -y blender)" >&2
    exit 2
fi

# Blender 3.4's importer opens the file with mode 'rU', which Python 3.11 rejects ('U' was
# removed); dropping the 'U' is all it needs.
read -r -d '' python <<'EOF' || true
import builtins, sys
import bpy

_open = builtins.open
def _open_without_u(file, mode="r", *args, **kwargs):
    if isinstance(mode, str):
        mode = mode.replace("U", "")
    return _open(file, mode, *args, **kwargs)
builtins.open = _open_without_u

path = sys.argv[sys.argv.index("--") + 1]
result = bpy.ops.import_anim.bvh(
    filepath=path, update_scene_fps=True, update_scene_duration=True
)
if "FINISHED" not in result:
    raise SystemExit("import failed: %r" % (result,))
# --factory-startup's scene holds a cube, a camera and a light: no other armature.
armatures = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"]
if len(armatures) != 1:
    raise SystemExit("expected one armature, found %d" % len(armatures))
armature = armatures[0]
action = armature.animation_data.action if armature.animation_data else None
# Every animated bone has one key per BVH frame.
frames = max((len(c.keyframe_points) for c in action.fcurves), default=0) if action else 0
render = bpy.context.scene.render
print("BLENDER_BVH joints=%d frames=%d fps=%.6f"
      % (len(armature.data.bones), frames, render.fps / render.fps_base))
EOF

start=$(date +%s.%N)
set +e
output=$("$blender" -b --factory-startup --python-exit-code 3 --python-expr "$python" -- "$file" 2>&1)
status=$?
set -e
end=$(date +%s.%N)
line=$(grep '^BLENDER_BVH ' <<<"$output" || true)
if [[ $status -ne 0 || -z $line ]]; then
    echo "$output" >&2
    echo "Blender could not import $file (exit $status)" >&2
    exit 2
fi

joints=$(sed -E 's/.*joints=([0-9]+).*/\1/' <<<"$line")
frames=$(sed -E 's/.*frames=([0-9]+).*/\1/' <<<"$line")
fps=$(sed -E 's/.*fps=([0-9.]+).*/\1/' <<<"$line")
printf '%s: Blender sees %s joints, %s frames, %s fps (%.1f s)\n' \
    "$file" "$joints" "$frames" "$fps" "$(awk -v a="$start" -v b="$end" 'BEGIN { print b - a }')"

if [[ $# -eq 4 ]]; then
    ok=1
    [[ $joints == "$2" ]] || { echo "joints: expected $2, Blender sees $joints" >&2; ok=0; }
    [[ $frames == "$3" ]] || { echo "frames: expected $3, Blender sees $frames" >&2; ok=0; }
    if ! awk -v a="$fps" -v b="$4" 'BEGIN { d = a - b; exit !(d < 0.001 && d > -0.001) }'; then
        echo "fps: expected $4, Blender sees $fps" >&2
        ok=0
    fi
    if [[ $ok -eq 0 ]]; then
        exit 1
    fi
    echo "OK"
fi
