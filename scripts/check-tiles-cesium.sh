#!/usr/bin/env bash
# Loads a `terawalk export --tiles` tileset in CesiumJS in headless Chromium and checks that
# every tile the view needs loads, down to full detail, without a failed tile or a page error;
# writes a screenshot of the model placed upright on an east-north-up frame.
#
#   scripts/check-tiles-cesium.sh TILESET_DIR [SCREENSHOT.png]
#
# TILESET_DIR holds tileset.json (e.g. `terawalk export plant.tw --tiles TILESET_DIR`).
# Needs: Debian's chromium-headless-shell (or chromium; installed with apt-get when missing and
# running as root), node and npm. CesiumJS and puppeteer-core (which drives the system Chromium,
# nothing downloaded besides the npm packages) are installed once into $TW_CESIUM_DIR (default
# ~/.cache/terawalk-cesium). WebGL runs on SwiftShader, Chromium's CPU renderer: no GPU needed.
# Exit status: 0 when the tileset loaded cleanly, 1 otherwise (the reasons are printed).
set -euo pipefail

tiles=${1:?usage: $0 TILESET_DIR [SCREENSHOT.png]}
shot=${2:-tileset-cesium.png}
[[ -f "$tiles/tileset.json" ]] || { echo "no $tiles/tileset.json" >&2; exit 1; }
tiles=$(cd "$tiles" && pwd)
shot=$(cd "$(dirname "$shot")" && pwd)/$(basename "$shot")
dir=${TW_CESIUM_DIR:-$HOME/.cache/terawalk-cesium}

browser=$(command -v chromium-headless-shell || command -v chromium || true)
if [[ -z "$browser" && -x /usr/lib/chromium/chromium-headless-shell ]]; then
    browser=/usr/lib/chromium/chromium-headless-shell
fi
if [[ -z "$browser" ]]; then
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium-headless-shell >/dev/null
    browser=$(command -v chromium-headless-shell || echo /usr/lib/chromium/chromium-headless-shell)
fi
mkdir -p "$dir"
if [[ ! -d "$dir/node_modules/cesium" || ! -d "$dir/node_modules/puppeteer-core" ]]; then
    (cd "$dir" && npm install --no-audit --no-fund --silent cesium@1.145.0 puppeteer-core@24 >/dev/null)
fi

cat > "$dir/check.mjs" <<'JS'
// Serves CesiumJS and the tileset from one local HTTP server, opens a page that loads the
// tileset framed whole, first at Cesium's default maximumScreenSpaceError (16), then at 1e-4 so
// that every tile in view refines to its full-detail leaves; prints what it saw.
import http from 'node:http';
import fs from 'node:fs';
import path from 'node:path';
import puppeteer from 'puppeteer-core';

const [browserPath, cesiumDir, tilesDir, shot] = process.argv.slice(2);
const types = { '.js': 'text/javascript', '.json': 'application/json', '.glb': 'model/gltf-binary',
  '.css': 'text/css', '.html': 'text/html', '.wasm': 'application/wasm' };
const page = `<!doctype html><html><head><script src="/cesium/Cesium.js"></script>
<link rel="stylesheet" href="/cesium/Widgets/widgets.css">
<style>html,body,#c{margin:0;width:100%;height:100%}</style></head><body><div id="c"></div><script>
window.report = (async () => {
  const widget = new Cesium.CesiumWidget('c', { globe: false, baseLayer: false, skyBox: false,
    skyAtmosphere: false, shadows: false });
  widget.scene.backgroundColor = Cesium.Color.WHITE;
  const loaded = [], failed = [];
  const tileset = await Cesium.Cesium3DTileset.fromUrl('/tiles/tileset.json');
  // Placed on an east-north-up frame (as a georeferenced model would be): the tileset's +Z, the
  // store's up axis, becomes the local vertical, so an upright model stands on the ground.
  tileset.modelMatrix = Cesium.Transforms.eastNorthUpToFixedFrame(Cesium.Cartesian3.fromDegrees(8.5, 47.4, 400));
  tileset.tileLoad.addEventListener((t) => loaded.push(t.geometricError));
  tileset.tileFailed.addEventListener((e) => failed.push(e.url + ': ' + e.message));
  widget.scene.primitives.add(tileset);
  const s = tileset.boundingSphere;
  widget.camera.viewBoundingSphere(s, new Cesium.HeadingPitchRange(0.6, -0.45, s.radius * 2.2));
  widget.camera.lookAtTransform(Cesium.Matrix4.IDENTITY);
  const settle = async () => {
    const done = new Promise((r) => tileset.allTilesLoaded.addEventListener(() => r('allTilesLoaded')));
    const timeout = new Promise((r) => setTimeout(() => r('timeout'), 120000));
    const how = await Promise.race([done, timeout]);
    await new Promise((r) => setTimeout(r, 500));
    return how;
  };
  const coarse = await settle();
  const coarseTiles = loaded.length, coarseFinest = Math.min(...loaded);
  tileset.maximumScreenSpaceError = 1e-4;
  const how = coarse === 'timeout' ? coarse : await settle();
  return { how, coarseTiles, coarseFinestError: coarseFinest, loaded: loaded.length,
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
const browser = await puppeteer.launch({ executablePath: browserPath, headless: true,
  args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'] });
const errors = [];
try {
  const tab = await browser.newPage();
  await tab.setViewport({ width: 960, height: 600 });
  tab.on('pageerror', (e) => errors.push(String(e)));
  tab.on('requestfailed', (r) => errors.push('request failed: ' + r.url()));
  await tab.goto(`http://127.0.0.1:${server.address().port}/`);
  const report = await tab.evaluate(() => window.report);
  await tab.screenshot({ path: shot });
  console.log(JSON.stringify({ ...report, pageErrors: errors }));
  const ok = !report.error && report.how === 'allTilesLoaded' && report.loaded > 0 &&
    report.failed.length === 0 && errors.length === 0 && report.finestError === 0;
  process.exitCode = ok ? 0 : 1;
} finally {
  await browser.close();
  server.close();
}
JS

node "$dir/check.mjs" "$browser" "$dir/node_modules/cesium/Build/Cesium" "$tiles" "$shot" \
    && echo "ok: $tiles loaded in CesiumJS, down to full detail; screenshot $shot" \
    || { echo "FAILED: $tiles (see the report above)" >&2; exit 1; }
