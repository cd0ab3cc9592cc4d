// report_check.mjs REPORT.html [SCREENSHOT.png]: opens a bake's report.html from file:// in a
// fresh headless Chromium (playwright-core), as a user double-clicking it in the output folder,
// and checks:
// - no page or console error, and no request but the page itself (every other is refused);
// - every plot is an inline <svg> with a title, a labelled x and y axis and tick labels;
// - the player: its two views (the blendshape clip evaluated by the page, the reference decoded
//   from its int16 data) agree at five frames within the report's error plus the quantization,
//   in 3D and as drawn (projected canvas positions), and differ (by 10 times that and 3 px)
//   between the first frame and the farthest of the others; keys are marked on the timeline;
//   pressing the arrow keys on the focused scrubber moves it: a new frame, new pixels on both
//   canvases, a new time readout;
// - html-validate's recommended rules pass.
// Prints one JSON line: { ok, issues, plots, frames, agreement, motion, scrub, bytes }.
//
// report_check.mjs SUMMARY.html: a batch's summary.html, from file:// the same way: no error,
// no request, valid HTML, every bake's link names an existing report.html, and a click on each
// sortable header orders the rows by that column (again: reversed). Prints
// { ok, issues, rows, links, sorted }.

import { existsSync, readFileSync, statSync } from 'node:fs';
import { join, resolve } from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { chromium } from 'playwright-core';
import { HtmlValidate } from 'html-validate';
import { runChecker } from './browser.mjs';

const CHROMIUM = '/usr/bin/chromium';
const ARGS = ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync'];
const TIMEOUT_MS = 600_000;

// Open `url` in a fresh headless Chromium, refusing (and recording) every other request, and
// run `work(page)`.
async function inChromium(url, issues, requests, work) {
  const profile = mkdtempSync(join(tmpdir(), 'blendsim-chromium-'));
  let context;
  try {
    context = await chromium.launchPersistentContext(profile, { executablePath: CHROMIUM, headless: true, args: ARGS, viewport: { width: 1200, height: 900 }, timeout: TIMEOUT_MS });
    context.setDefaultTimeout(TIMEOUT_MS);
    await context.route('**/*', (route) => {
      const u = route.request().url();
      if (u === url) return route.continue();
      requests.push(u);
      return route.abort();
    });
    const page = context.pages()[0] ?? (await context.newPage());
    page.on('pageerror', (e) => issues.push(`page error: ${e.message}`));
    page.on('console', (m) => m.type() === 'error' && issues.push(`console error: ${m.text()}`));
    await page.goto(url, { waitUntil: 'load' });
    return await work(page);
  } finally {
    await context?.close();
    rmSync(profile, { recursive: true, force: true });
  }
}

async function validate(path, issues) {
  const validator = new HtmlValidate({ extends: ['html-validate:recommended'] });
  const report = await validator.validateString(readFileSync(path, 'utf8'), path);
  for (const r of report.results) for (const m of r.messages) issues.push(`html-validate ${m.ruleId} at ${m.line}:${m.column}: ${m.message}`);
}

async function summaryPage(path) {
  const url = pathToFileURL(path).href;
  const issues = [];
  const requests = [];
  await validate(path, issues);
  const result = { ok: false, issues };
  await inChromium(url, issues, requests, async (page) => {
    const links = await page.evaluate(() => [...document.querySelectorAll('#summary tbody tr td:first-child a')].map((a) => a.href));
    result.rows = await page.evaluate(() => document.querySelectorAll('#summary tbody tr').length);
    result.links = links;
    for (const l of links) {
      if (!l.startsWith('file://') || !existsSync(fileURLToPath(l))) issues.push(`link ${l} names no file`);
    }
    const headers = await page.evaluate(() => [...document.querySelectorAll('#summary th[data-sort]')].map((th) => th.dataset.sort));
    result.sorted = [];
    for (const h of headers) {
      for (const dir of [1, -1]) {
        await page.click(`#summary th[data-sort="${h}"]`);
        const values = await page.evaluate((h) => {
          const k = [...document.querySelectorAll('#summary th')].findIndex((th) => th.dataset.sort === h);
          return [...document.querySelectorAll('#summary tbody tr')].map((r) => r.cells[k].dataset.value ?? r.cells[k].textContent);
        }, h);
        const nums = values.filter((v) => v !== '').map(Number);
        const ordered = nums.every((x, i) => i === 0 || (dir > 0 ? nums[i - 1] <= x : nums[i - 1] >= x));
        if (!ordered) issues.push(`sorting by ${h} (${dir > 0 ? 'ascending' : 'descending'}) gave ${JSON.stringify(values)}`);
        result.sorted.push({ column: h, dir, values });
      }
    }
  });
  for (const r of requests) issues.push(`network request: ${r}`);
  result.ok = issues.length === 0;
  console.log(JSON.stringify(result));
  return result.ok ? 0 : 1;
}

async function main() {
  const [file, screenshot] = process.argv.slice(2);
  if (file.endsWith('summary.html')) return summaryPage(resolve(file));
  const path = resolve(file);
  const url = pathToFileURL(path).href;
  const issues = [];
  const requests = [];
  const result = { ok: false, issues, bytes: statSync(path).size };

  await validate(path, issues);
  await inChromium(url, issues, requests, async (page) => {
    await page.waitForFunction(() => window.blendsimPlayer !== undefined, null, { timeout: TIMEOUT_MS });

    result.plots = await page.evaluate(() =>
      [...document.querySelectorAll('svg.plot')].map((svg) => ({
        id: svg.id,
        title: svg.querySelector('title')?.textContent ?? '',
        x: svg.querySelector('.x-label')?.textContent ?? '',
        y: svg.querySelector('.y-label')?.textContent ?? '',
        xTicks: svg.querySelectorAll('.x-tick').length,
        yTicks: svg.querySelectorAll('.y-tick').length,
        marks: svg.querySelectorAll('.mark').length,
        shapes: svg.querySelectorAll('polyline, circle, rect.bar').length,
        bars: svg.querySelectorAll('rect.bar').length,
      })),
    );
    for (const p of result.plots) {
      // A bar plot of one format has one x tick (its name); a line plot needs two.
      const xTicks = p.bars > 0 ? 1 : 2;
      if (!p.title || !p.x || !p.y || p.xTicks < xTicks || p.yTicks < 2 || p.shapes === 0) issues.push(`plot ${p.id} lacks a title, axis labels, ticks or data: ${JSON.stringify(p)}`);
    }

    // The two views at five frames: positions (scene units) and as drawn (pixels).
    const probe = await page.evaluate(() => {
      const s = window.blendsimPlayer;
      // The largest distance between the points of a and b (3 numbers each), over `dims` of them.
      const far = (a, b, dims) => {
        let m = 0;
        for (let i = 0; i < a.length; i += 3) {
          let d = 0;
          for (let k = 0; k < dims; k++) d += (a[i + k] - b[i + k]) ** 2;
          m = Math.max(m, Math.sqrt(d));
        }
        return m;
      };
      const frames = [0, Math.floor(s.frames / 4), Math.floor(s.frames / 2), Math.floor((3 * s.frames) / 4), s.frames - 1];
      const at = frames.map((f) => {
        s.setFrame(f);
        return {
          frame: f,
          time: s.times[f],
          distance: far(s.blendshape(f), s.reference(f), 3),
          allowed: s.error[f] + Math.sqrt(3) * s.step + 1e-6,
          pixels: far(s.drawn.blendshape, s.drawn.reference, 2),
        };
      });
      // Motion: the probed frame farthest from the first (the demo loops: its middle is the
      // rest pose again).
      s.setFrame(0);
      const first = { positions: s.reference(0), drawn: Float32Array.from(s.drawn.reference) };
      let motion = { frames: [0, 0], distance: 0, pixels: 0 };
      for (const f of frames.slice(1)) {
        s.setFrame(f);
        const m = { frames: [0, f], distance: far(first.positions, s.reference(f), 3), pixels: far(first.drawn, s.drawn.reference, 2) };
        if (m.distance > motion.distance) motion = m;
      }
      s.setFrame(0);
      const keys = document.querySelectorAll('#key-frames option').length;
      return { frames: s.frames, keyTimes: s.keyTimes.length, keys, at, motion };
    });
    result.frames = probe.frames;
    result.agreement = probe.at;
    result.motion = probe.motion;
    for (const a of probe.at) {
      if (!(a.distance <= a.allowed)) issues.push(`frame ${a.frame}: the views differ by ${a.distance}, more than ${a.allowed}`);
      if (!(a.pixels <= 1)) issues.push(`frame ${a.frame}: the views are drawn ${a.pixels} px apart`);
    }
    const worst = Math.max(...probe.at.map((a) => a.allowed));
    if (!(probe.motion.distance > 10 * worst && probe.motion.pixels > 3)) issues.push(`the reference barely moves between frames 0 and ${probe.motion.frames[1]}: ${JSON.stringify(probe.motion)}`);
    if (probe.keys !== probe.keyTimes || probe.keys < 2) issues.push(`${probe.keys} key marks on the timeline for ${probe.keyTimes} keys`);

    // The scrubber as a user moves it: focus, then arrow keys.
    const before = await page.evaluate(() => ({
      frame: window.blendsimPlayer.frame,
      time: document.getElementById('time').textContent,
      left: document.getElementById('view-blendshape').toDataURL(),
      right: document.getElementById('view-reference').toDataURL(),
    }));
    await page.focus('#scrub');
    const steps = Math.max(1, Math.floor(probe.frames / 3));
    for (let i = 0; i < steps; i++) await page.keyboard.press('ArrowRight');
    const after = await page.evaluate(() => ({
      frame: window.blendsimPlayer.frame,
      time: document.getElementById('time').textContent,
      left: document.getElementById('view-blendshape').toDataURL(),
      right: document.getElementById('view-reference').toDataURL(),
    }));
    result.scrub = { from: before.frame, to: after.frame, time: [before.time, after.time] };
    if (after.frame !== before.frame + steps) issues.push(`the scrubber moved the player from frame ${before.frame} to ${after.frame}, not ${before.frame + steps}`);
    if (after.left === before.left || after.right === before.right) issues.push('scrubbing did not redraw both views');
    if (after.time === before.time) issues.push('scrubbing did not update the time');
    if (screenshot) await page.screenshot({ path: screenshot, fullPage: true });
  });
  for (const r of requests) issues.push(`network request: ${r}`);
  result.ok = issues.length === 0;
  console.log(JSON.stringify(result));
  return result.ok ? 0 : 1;
}

runChecker('report_check.mjs', main, TIMEOUT_MS + 60_000);
