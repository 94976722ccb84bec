#!/usr/bin/env bash
# Installs headless Chromium from npm into the folder $1, for machines without a system Chromium
# (the web test's fallback; `.ci/run` installs Debian's `chromium` instead). The npm package
# `@sparticuz/chromium` carries the browser itself (Brotli-compressed, with the NSS libraries,
# SwiftShader and a few fonts), so this needs only Node, npm and tar: no download beside the
# npm registry, no root. Leaves `$1/chromium`; run it with `LD_LIBRARY_PATH=$1/lib` and
# `FONTCONFIG_PATH=$1/fonts`.
set -euo pipefail
dir=$1
version=153.0.0
mkdir -p "$dir"
npm install --silent --no-audit --no-fund --prefix "$dir" "@sparticuz/chromium@$version"
bin="$dir/node_modules/@sparticuz/chromium/bin"
unbrotli() { node -e "process.stdin.pipe(require('zlib').createBrotliDecompress()).pipe(process.stdout)" < "$1"; }
for archive in al2023 swiftshader; do unbrotli "$bin/$archive.tar.br" | tar -x -C "$dir"; done
mkdir -p "$dir/fonts"
unbrotli "$bin/fonts.tar.br" | tar -x -C "$dir/fonts"
cat > "$dir/fonts/fonts.conf" <<CONF
<?xml version="1.0"?>
<!DOCTYPE fontconfig SYSTEM "fonts.dtd">
<fontconfig><dir>$dir/fonts/fonts</dir><cachedir>$dir/fonts/cache</cachedir></fontconfig>
CONF
unbrotli "$bin/chromium.br" > "$dir/chromium.part"
chmod 755 "$dir/chromium.part"
mv "$dir/chromium.part" "$dir/chromium"
