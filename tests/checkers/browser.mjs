// The browser side of the checkers that render in Chromium (render_check.mjs,
// texture_check.mjs): a local server for the page, three.js's ES modules and the files under
// test, a fresh headless Chromium driven by playwright-core, and the process's time limit.

import { mkdtempSync, readFileSync, rmSync } from 'node:fs';
import { createServer } from 'node:http';
import { tmpdir } from 'node:os';
import { dirname, extname, join, resolve, sep } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const THREE_ROOT = join(dirname(fileURLToPath(import.meta.url)), 'node_modules', 'three');
const CHROMIUM = '/usr/bin/chromium';
// --user-data-dir is given through launchPersistentContext (playwright refuses it in args).
const ACTION_TIMEOUT_MS = 600_000;
const ARGS = ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync'];

/**
 * The start of a checker's page: the import map (`three` and `three/addons/` from the served
 * node_modules), then a module script that imports THREE, GLTFLoader and `loaders` (names of
 * three/addons/loaders modules, e.g. 'OBJLoader') and makes `W`, `H`, `renderer` (no
 * antialiasing, a readable drawing buffer, pixel ratio 1), `gl` and `scene`. The page goes on
 * with its own script and closes the script, body and html.
 */
export function pageStart(title, size, loaders = []) {
  const imports = ['GLTFLoader', ...loaders].map((l) => `import { ${l} } from 'three/addons/loaders/${l}.js';`).join('\n');
  return `<!doctype html>
<html><head><meta charset="utf-8"><title>${title}</title><link rel="icon" href="data:,">
<style>html, body { margin: 0; background: #000; }</style>
<script type="importmap">{"imports": {"three": "/three/build/three.module.js", "three/addons/": "/three/examples/jsm/"}}</script>
</head><body>
<script type="module">
import * as THREE from 'three';
${imports}

const W = ${size.width}, H = ${size.height};
const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
renderer.setPixelRatio(1);
renderer.setSize(W, H);
document.body.appendChild(renderer.domElement);
const gl = renderer.getContext();
const scene = new THREE.Scene();`;
}

/**
 * Serve `page` at `/`, three.js under `/three/`, and whatever `route(pathname)` returns as
 * `[body, contentType]` (null: 404) on 127.0.0.1 at an ephemeral port.
 */
export function serve(page, route) {
  const server = createServer((req, res) => {
    const url = new URL(req.url, 'http://127.0.0.1');
    let found = null;
    if (url.pathname === '/') found = [page, 'text/html'];
    else if (url.pathname.startsWith('/three/')) {
      const path = resolve(THREE_ROOT, '.' + decodeURIComponent(url.pathname.slice('/three'.length)));
      if (path.startsWith(THREE_ROOT + sep)) {
        try {
          found = [readFileSync(path), extname(path) === '.js' ? 'text/javascript' : 'application/octet-stream'];
        } catch {}
      }
    } else found = route(url.pathname);
    if (!found || found[0] === null || found[0] === undefined) {
      res.writeHead(404).end();
      return;
    }
    res.writeHead(200, { 'Content-Type': found[1], 'Cache-Control': 'no-store' }).end(found[0]);
  });
  return new Promise((ok) => server.listen(0, '127.0.0.1', () => ok(server)));
}

/**
 * Open `server`'s page in a fresh headless Chromium of `viewport` size, wait for the page to
 * set `window.pageReady`, and run `work(page)`; page errors and console errors go to `issues`.
 * The browser, the server and the profile folder are gone afterwards, whatever happened.
 */
export async function inChromium(server, viewport, issues, work) {
  const profile = mkdtempSync(join(tmpdir(), 'blendsim-chromium-'));
  let context;
  try {
    // Playwright's own limits (30 s per action and navigation, 180 s to launch) only turn a
    // hang into a failure; on a loaded machine (CI's 2 cores at load 20, software WebGL) a
    // slow but healthy browser must not reach them. The checker's TIMEOUT_MS bounds the whole.
    context = await chromium.launchPersistentContext(profile, { executablePath: CHROMIUM, headless: true, args: ARGS, viewport, timeout: ACTION_TIMEOUT_MS });
    context.setDefaultTimeout(ACTION_TIMEOUT_MS);
    context.setDefaultNavigationTimeout(ACTION_TIMEOUT_MS);
    const page = context.pages()[0] ?? (await context.newPage());
    page.on('pageerror', (e) => issues.push(`page error: ${e.message}`));
    page.on('console', (m) => m.type() === 'error' && issues.push(`console error: ${m.text()}`));
    await page.goto(`http://127.0.0.1:${server.address().port}/`);
    await page.waitForFunction(() => window.pageReady === true, null, { timeout: ACTION_TIMEOUT_MS });
    return await work(page);
  } finally {
    await context?.close();
    server.close();
    rmSync(profile, { recursive: true, force: true });
  }
}

/**
 * Run `main` (resolving to an exit code) as the process, failing with a one-line JSON summary
 * (`failed` plus the issue) on an exception or after `timeoutMs`.
 */
export function runChecker(name, main, timeoutMs, failed = {}) {
  const fail = (issue) => console.log(JSON.stringify({ ok: false, issues: [issue], ...failed }));
  const timer = setTimeout(() => {
    console.error(`${name}: no result after ${timeoutMs / 1000} s`);
    fail('timeout');
    process.exit(1);
  }, timeoutMs);
  main().then(
    (code) => { clearTimeout(timer); process.exit(code); },
    (e) => {
      console.error(e?.stack ?? String(e));
      fail(String(e?.message ?? e));
      process.exit(1);
    },
  );
}
