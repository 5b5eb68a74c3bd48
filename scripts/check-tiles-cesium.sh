#!/usr/bin/env bash
# Loads a `terawalk export --tiles` tileset in CesiumJS in headless Chromium and checks that
# every tile the view needs loads, down to full detail, without a failed tile or a page error;
# writes a screenshot of the model placed upright on an east-north-up frame.
#
#   scripts/check-tiles-cesium.sh TILESET_DIR [SCREENSHOT.png]
#   scripts/check-tiles-cesium.sh --install        # only install what it needs (CI's setup)
#   scripts/check-tiles-cesium.sh --check-setup    # exit 0 when all is installed; installs nothing
#
# TILESET_DIR holds tileset.json (e.g. `terawalk export plant.tw --tiles TILESET_DIR`).
# Needs: Debian's chromium-headless-shell (or chromium; installed with apt-get when missing and
# running as root), node and npm. CesiumJS and puppeteer-core (which drives the system Chromium,
# nothing downloaded besides the npm packages) are installed once into $TW_CESIUM_DIR (default
# ~/.cache/terawalk-cesium), at pinned versions: that folder (and npm's cache, ~/.npm) is what a
# CI machine caches; with a warm npm cache the install takes seconds. WebGL runs on SwiftShader,
# Chromium's CPU renderer: no GPU needed.
# The check never hangs: it gives up after $TW_CESIUM_TIMEOUT seconds (default 120), the npm
# install after 600 s.
# Exit status: 0 when the tileset loaded cleanly, 1 otherwise (each reason on a line starting
# with "FAILED:", on standard error). Standard output holds the page's report as one JSON line
# (tiles loaded, failed tiles, page errors), for tests to read.
set -euo pipefail

dir=${TW_CESIUM_DIR:-$HOME/.cache/terawalk-cesium}
limit=${TW_CESIUM_TIMEOUT:-120}
[[ "$limit" =~ ^[0-9]+$ && "$limit" -ge 30 ]] || { echo "FAILED: TW_CESIUM_TIMEOUT=$limit: a number of seconds, at least 30" >&2; exit 1; }
# Exact versions: a cached $TW_CESIUM_DIR stays valid until these change (then it is reinstalled).
cesium_version=1.145.0
puppeteer_version=24.43.1

find_browser() {
    command -v chromium-headless-shell || command -v chromium \
        || { [[ -x /usr/lib/chromium/chromium-headless-shell ]] && echo /usr/lib/chromium/chromium-headless-shell; } \
        || true
}
# Whether $dir holds the pinned npm packages.
have_packages() {
    grep -qs "\"version\": \"$cesium_version\"" "$dir/node_modules/cesium/package.json" \
        && grep -qs "\"version\": \"$puppeteer_version\"" "$dir/node_modules/puppeteer-core/package.json"
}
# Prints what is missing, one line each; fails when anything is.
check_setup() {
    local missing=0
    [[ -n "$(find_browser)" ]] || { echo "missing: Chromium (apt-get install chromium-headless-shell)" >&2; missing=1; }
    command -v node >/dev/null || { echo "missing: node (apt-get install nodejs)" >&2; missing=1; }
    have_packages || { echo "missing: cesium@$cesium_version and puppeteer-core@$puppeteer_version in $dir (run $0 --install)" >&2; missing=1; }
    return $missing
}
install() {
    if [[ -z "$(find_browser)" ]]; then
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium-headless-shell >/dev/null
    fi
    if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends nodejs npm >/dev/null
    fi
    if ! have_packages; then
        mkdir -p "$dir"
        # No install scripts: both packages ship what is used (Build/Cesium, puppeteer-core's
        # JavaScript); puppeteer-core downloads no browser.
        (cd "$dir" && timeout 600 npm install --no-audit --no-fund --silent --ignore-scripts --omit=dev \
            "cesium@$cesium_version" "puppeteer-core@$puppeteer_version" >/dev/null) \
            || { echo "FAILED: npm install into $dir" >&2; exit 1; }
    fi
}

case "${1:-}" in
    --install) install; check_setup; exit ;;
    --check-setup) check_setup; exit ;;
esac

tiles=${1:?usage: $0 TILESET_DIR [SCREENSHOT.png] | --install | --check-setup}
shot=${2:-tileset-cesium.png}
[[ -f "$tiles/tileset.json" ]] || { echo "FAILED: no $tiles/tileset.json" >&2; exit 1; }
tiles=$(cd "$tiles" && pwd)
shot=$(cd "$(dirname "$shot")" && pwd)/$(basename "$shot")
check_setup 2>/dev/null || install
browser=$(find_browser)
# In $dir, where node finds puppeteer-core; one file per run, so that runs can overlap.
check="$dir/check-$$.mjs"
trap 'rm -f "$check"' EXIT
cat > "$check" <<'JS'
// Serves CesiumJS and the tileset from one local HTTP server, opens a page that loads the
// tileset framed whole, first at Cesium's default maximumScreenSpaceError (16), then at 1e-4 so
// that every tile in view refines to its full-detail leaves; prints why it failed, if it did,
// and what it saw (one JSON line, last).
import http from 'node:http';
import fs from 'node:fs';
import path from 'node:path';
import puppeteer from 'puppeteer-core';

const [browserPath, cesiumDir, tilesDir, shot, limitS] = process.argv.slice(2);
// The page's waits end this long after it starts, leaving time to start Chromium before and to
// take the screenshot after, within the script's overall limit.
const pageBudgetMs = (Number(limitS) - 20) * 1000;
const types = { '.js': 'text/javascript', '.json': 'application/json', '.glb': 'model/gltf-binary',
  '.css': 'text/css', '.html': 'text/html', '.wasm': 'application/wasm' };
// The credits (Cesium's logo) are hidden: the screenshot is the model on a plain background.
const page = `<!doctype html><html><head><script src="/cesium/Cesium.js"></script>
<link rel="stylesheet" href="/cesium/Widgets/widgets.css">
<style>html,body,#c{margin:0;width:100%;height:100%}.cesium-widget-credits{display:none!important}</style>
</head><body><div id="c"></div><script>
window.report = (async () => {
  const deadline = Date.now() + ${pageBudgetMs};
  const widget = new Cesium.CesiumWidget('c', { globe: false, baseLayer: false, skyBox: false,
    skyAtmosphere: false, shadows: false });
  widget.scene.backgroundColor = Cesium.Color.WHITE;
  const loaded = [], uris = new Set(), failed = [];
  const tileset = await Cesium.Cesium3DTileset.fromUrl('/tiles/tileset.json');
  // Placed on an east-north-up frame (as a georeferenced model would be): the tileset's +Z, the
  // store's up axis, becomes the local vertical, so an upright model stands on the ground.
  tileset.modelMatrix = Cesium.Transforms.eastNorthUpToFixedFrame(Cesium.Cartesian3.fromDegrees(8.5, 47.4, 400));
  tileset.tileLoad.addEventListener((t) => { loaded.push(t.geometricError); uris.add(t.content.url); });
  tileset.tileFailed.addEventListener((e) => failed.push(e.url + ': ' + e.message));
  widget.scene.primitives.add(tileset);
  const s = tileset.boundingSphere;
  widget.camera.viewBoundingSphere(s, new Cesium.HeadingPitchRange(0.6, -0.45, s.radius * 2.2));
  widget.camera.lookAtTransform(Cesium.Matrix4.IDENTITY);
  const settle = async () => {
    const done = new Promise((r) => tileset.allTilesLoaded.addEventListener(() => r('allTilesLoaded')));
    const timeout = new Promise((r) => setTimeout(() => r('timeout'), Math.max(0, deadline - Date.now())));
    const how = await Promise.race([done, timeout]);
    await new Promise((r) => setTimeout(r, 500));
    return how;
  };
  const coarse = await settle();
  const coarseTiles = loaded.length, coarseFinest = Math.min(...loaded);
  tileset.maximumScreenSpaceError = 1e-4;
  const how = coarse === 'timeout' ? coarse : await settle();
  return { how, coarseTiles, coarseFinestError: coarseFinest, loaded: loaded.length, tiles: uris.size,
    finestError: Math.min(...loaded), failed, radius: s.radius };
})().catch((e) => ({ error: String(e && e.stack || e) }));
</script></body></html>`;

const server = http.createServer((req, res) => {
  const url = decodeURIComponent(req.url.split('?')[0]);
  let file = null;
  if (url === '/') { res.writeHead(200, { 'content-type': 'text/html' }); return res.end(page); }
  if (url.startsWith('/cesium/')) file = path.join(cesiumDir, url.slice(8));
  if (url.startsWith('/tiles/')) file = path.join(tilesDir, url.slice(7));
  if (!file || !fs.existsSync(file) || !fs.statSync(file).isFile()) { res.writeHead(404); return res.end(); }
  res.writeHead(200, { 'content-type': types[path.extname(file)] || 'application/octet-stream' });
  fs.createReadStream(file).pipe(res);
});
await new Promise((r) => server.listen(0, '127.0.0.1', r));
// `pipe`: Chromium talks over its standard streams, so it exits with this process however that
// ends (the script's timeout included).
const browser = await puppeteer.launch({ executablePath: browserPath, headless: true, pipe: true,
  protocolTimeout: pageBudgetMs + 15000,
  args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'] });
const errors = [];
try {
  const tab = await browser.newPage();
  await tab.setViewport({ width: 960, height: 600 });
  tab.on('pageerror', (e) => errors.push(String(e)));
  tab.on('requestfailed', (r) => errors.push('request failed: ' + r.url()));
  tab.on('response', (r) => { if (r.status() >= 400) errors.push(`HTTP ${r.status()}: ${r.url()}`); });
  await tab.goto(`http://127.0.0.1:${server.address().port}/`, { timeout: pageBudgetMs });
  const report = await tab.evaluate(() => window.report);
  await tab.screenshot({ path: shot });
  const why = [];
  if (report.error) why.push('the page threw: ' + report.error);
  else {
    if (report.how !== 'allTilesLoaded') why.push(`tiles still loading after ${limitS - 20} s (${report.loaded} loaded)`);
    if (report.loaded === 0) why.push('no tile loaded');
    for (const f of report.failed) why.push('tile failed: ' + f);
    if (report.loaded > 0 && report.finestError !== 0) why.push(`not refined to full detail: finest geometricError ${report.finestError}`);
  }
  for (const e of errors) why.push('page error: ' + e);
  for (const w of why) console.error('FAILED: ' + w);
  console.log(JSON.stringify({ ...report, pageErrors: errors }));
  process.exitCode = why.length === 0 ? 0 : 1;
} finally {
  await browser.close();
  server.close();
}
JS

status=0
timeout -k 5 "$limit" node "$check" "$browser" "$dir/node_modules/cesium/Build/Cesium" "$tiles" "$shot" "$limit" \
    || status=$?
case $status in
    0) echo "ok: $tiles loaded in CesiumJS, down to full detail; screenshot $shot" ;;
    124 | 137) echo "FAILED: $tiles: CesiumJS check timed out after $limit s (TW_CESIUM_TIMEOUT)" >&2; exit 1 ;;
    *) echo "FAILED: $tiles (exit status $status; reasons above)" >&2; exit 1 ;;
esac
