// What the two glTF checkers share (gltf_check.mjs: blendsim's glb output; gltf_cache_check.mjs:
// the glTF clips blendsim reads): the Khronos validator, three.js's GLTFLoader in plain Node,
// the clips played once by an AnimationMixer, the comparison with EXPECTED.points at each time,
// and the one-line JSON summary. A module, not a command.

import { readFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { MeshoptDecoder } from 'three/addons/libs/meshopt_decoder.module.js';

const require = createRequire(import.meta.url);
const validator = require('gltf-validator');

const SEVERITY = ['error', 'warning', 'info', 'hint'];

/** The folder of `file`, for its external resources. */
function folderOf(file) {
  return file.includes('/') ? file.slice(0, file.lastIndexOf('/') + 1) : './';
}

/** gltf-validator on the bytes: its counts into summary.validator, every error and warning
 *  into summary.issues (the checkers require zero of both). */
export async function validate(bytes, file, summary) {
  const report = await validator.validateBytes(bytes, {
    maxIssues: 0,
    writeTimestamp: false,
    externalResourceFunction: (uri) => Promise.resolve(new Uint8Array(readFileSync(folderOf(file) + decodeURIComponent(uri)))),
  });
  const i = report.issues;
  summary.validator = {
    version: report.validatorVersion,
    errors: i.numErrors,
    warnings: i.numWarnings,
    infos: i.numInfos,
    hints: i.numHints,
    info_codes: [...new Set(i.messages.filter((m) => m.severity >= 2).map((m) => m.code))],
  };
  for (const m of i.messages.filter((m) => m.severity <= 1)) {
    summary.issues.push(`validator ${SEVERITY[m.severity]} ${m.code} at ${m.pointer ?? m.offset}: ${m.message}`);
  }
}

/** three.js's GLTFLoader on a .glb, or on a .gltf whose external buffers are inlined as data
 *  URIs (no fetch in Node). Plain Node cannot decode images (no DOM): textures load as empty
 *  placeholders; the validator checks the embedded images and texture_check.mjs renders them. */
export function parse(bytes, file) {
  // EXT_meshopt_compression files need three's meshopt decoder (WebAssembly, runs in Node).
  const loader = new GLTFLoader()
    .setMeshoptDecoder(MeshoptDecoder)
    .register(() => ({ name: 'blendsim_no_image_decoding', loadTexture: () => Promise.resolve(new THREE.Texture()) }));
  if (new TextDecoder().decode(bytes.subarray(0, 4)) !== 'glTF') {
    const json = JSON.parse(new TextDecoder().decode(bytes));
    for (const b of json.buffers ?? []) {
      if (b.uri && !b.uri.startsWith('data:')) {
        b.uri = 'data:application/octet-stream;base64,' + readFileSync(folderOf(file) + decodeURIComponent(b.uri)).toString('base64');
      }
    }
    return new Promise((resolve, reject) => loader.parse(JSON.stringify(json), '', resolve, reject));
  }
  const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
  return new Promise((resolve, reject) => loader.parse(buffer, '', resolve, reject));
}

/** The diagonal of the box holding every point of every frame. */
export function diagonal(frames) {
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (const f of frames) for (const p of f) for (let d = 0; d < 3; d++) {
    lo[d] = Math.min(lo[d], p[d]);
    hi[d] = Math.max(hi[d], p[d]);
  }
  return Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
}

/** The largest distance between corresponding points; NaN when any point is NaN (Math.max
 *  alone would drop it and hide a broken file behind a zero). */
export function maxDistance(a, b) {
  let worst = 0;
  for (let i = 0; i < a.length; i++) {
    const d = Math.hypot(a[i][0] - b[i][0], a[i][1] - b[i][1], a[i][2] - b[i][2]);
    if (Number.isNaN(d)) return NaN;
    worst = Math.max(worst, d);
  }
  return worst;
}

/** An AnimationMixer on `scene` playing each clip once, holding its last pose at the end
 *  instead of wrapping to the start. Returns the mixer and its actions. */
export function play(scene, clips) {
  const mixer = new THREE.AnimationMixer(scene);
  const actions = clips.map((clip) => {
    const action = mixer.clipAction(clip);
    action.setLoop(THREE.LoopOnce);
    action.clampWhenFinished = true;
    return action.play();
  });
  return { mixer, actions };
}

/** At each EXPECTED time: the clips from their start to that time, then `pointsAt(t, i)` gives
 *  `[got, want]` (or null after pushing its own issue). The largest distance over the diagonal
 *  of EXPECTED.points, its time, and how many times moved at all from the first one go into
 *  the summary; over EXPECTED.tolerance, a NaN, or a file whose points never move while the
 *  expected ones do is an issue. */
export function compare(expected, summary, { mixer, actions }, pointsAt) {
  const tolerance = expected.tolerance ?? 1e-5;
  const scale = Math.max(diagonal(expected.points), 1e-30);
  let worst = 0;
  let worstTime = null;
  let first = null;
  let moved = 0;
  expected.times.forEach((t, i) => {
    actions.forEach((a) => a.reset());
    mixer.setTime(t);
    const pair = pointsAt(t, i);
    if (!pair) return;
    const [got, want] = pair;
    if (got.length !== want.length) {
      summary.issues.push(`time ${t}: three.js has ${got.length} points, expected ${want.length}`);
      return;
    }
    const error = maxDistance(got, want) / scale;
    if (Number.isNaN(error)) summary.issues.push(`time ${t}: a point is NaN`);
    else if (error > worst) [worst, worstTime] = [error, t];
    if (first === null) first = got;
    else if (maxDistance(got, first) > 0) moved += 1;
  });
  const expectedMoves = expected.points.some((p) => maxDistance(p, expected.points[0]) > 0);
  Object.assign(summary, { times: expected.times.length, max_error: worst, worst_time: worstTime, moving_times: moved });
  if (worst > tolerance) summary.issues.push(`max error ${worst.toPrecision(3)} (relative to the bbox diagonal) at ${worstTime} s exceeds ${tolerance}`);
  if (expectedMoves && moved === 0) summary.issues.push('three.js shows the same points at every time, but the expected points move: the animation did not play');
}

/** Print the issues and the summary line; the exit code. */
export function finish(summary) {
  summary.ok = summary.issues.length === 0;
  for (const issue of summary.issues) console.error(`${summary.file}: ${issue}`);
  console.log(JSON.stringify(summary));
  return summary.ok ? 0 : 1;
}

/** Run a checker's main: its exit code, or 1 with the exception as the summary's issue. */
export function run(main) {
  main().then(
    (code) => process.exit(code),
    (e) => {
      console.error(e?.stack ?? String(e));
      console.log(JSON.stringify({ ok: false, issues: [String(e)] }));
      process.exit(1);
    },
  );
}
