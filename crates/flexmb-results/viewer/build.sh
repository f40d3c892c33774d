#!/bin/sh
# Rebuilds three.bundle.min.js, the three.js bundle that flexmb-results embeds in its HTML
# animation (src/view.rs include_str!s it, so `cargo build` needs no npm). Run it after a
# change of the pinned versions in package.json, and commit the bundle with the lock file:
#
#   cd crates/flexmb-results/viewer && sh build.sh
#
# It installs exactly what package-lock.json pins (npm ci), bundles entry.js into one
# minified classic script (an IIFE: no modules, no network) and copies three.js's licence.
set -eu
cd "$(dirname "$0")"
npm ci --no-audit --no-fund
version=$(node -p "require('./node_modules/three/package.json').version")
./node_modules/.bin/esbuild entry.js --bundle --minify --format=iife --target=es2020 \
  --legal-comments=none --outfile=three.bundle.min.js \
  --banner:js="/*! three.js $version and its OrbitControls (MIT licence, Copyright 2010-2026 three.js authors: THREE-LICENSE.txt), bundled for flexmb by viewer/build.sh */"
cp node_modules/three/LICENSE THREE-LICENSE.txt
ls -l three.bundle.min.js
