#!/usr/bin/env bash
# Rebuilds the view page's vendor bundle (three.js, GLTFLoader, OrbitControls, three-vrm) from
# the locked npm packages into ../vendor.min.js.gz, which the danced binary embeds. Neither the
# Rust build nor CI needs npm: the bundle is committed. Licence comments are kept inline.
set -euo pipefail
cd "$(dirname "$0")"
npm ci --no-audit --no-fund
node_modules/@esbuild/linux-x64/bin/esbuild entry.js --bundle --format=esm --minify \
  --legal-comments=inline --target=es2020 --outfile=vendor.min.js
# gzip -n: no name or time stamp, so the same packages give the same bytes.
gzip -9 -n -c vendor.min.js > ../vendor.min.js.gz
ls -l vendor.min.js ../vendor.min.js.gz
rm vendor.min.js
