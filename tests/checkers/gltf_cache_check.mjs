#!/usr/bin/env node
// Evaluate a glTF clip the way a real client does, to check blendsim's cache reader: the
// Khronos glTF validator, then three.js's GLTFLoader + AnimationMixer playing ONE named
// animation, with every vertex deformed on the CPU (morph targets and skinning) in world space.
//
// usage: node gltf_cache_check.mjs FILE.glb|FILE.gltf EXPECTED.json
//
// 1. gltf-validator: zero errors and zero warnings (every issue printed otherwise).
// 2. three.js: the clip named EXPECTED.animation (or the only one) plays alone; at each
//    EXPECTED time: mixer.setTime(t), then for every mesh of the scene in traversal order,
//    Mesh.getVertexPosition (morph influences, and bone transforms for a SkinnedMesh) times
//    the mesh's world matrix. The points of all meshes, concatenated, are compared with
//    EXPECTED.points: the largest distance divided by their bounding-box diagonal must be
//    <= tolerance.
//
// EXPECTED.json: {"animation": "name" | null, "times": [...], "points": [[[x,y,z], ...], ...],
// "tolerance": 1e-5}. Prints issues to stderr and a one-line JSON summary to stdout; exit code
// 0 when everything passes, 1 otherwise.

import { readFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';

const require = createRequire(import.meta.url);
const validator = require('gltf-validator');

async function validate(bytes, file, summary) {
  const dir = file.includes('/') ? file.slice(0, file.lastIndexOf('/') + 1) : './';
  const report = await validator.validateBytes(bytes, {
    maxIssues: 0,
    writeTimestamp: false,
    externalResourceFunction: (uri) => Promise.resolve(new Uint8Array(readFileSync(dir + decodeURIComponent(uri)))),
  });
  const i = report.issues;
  summary.validator = { version: report.validatorVersion, errors: i.numErrors, warnings: i.numWarnings };
  for (const m of i.messages.filter((m) => m.severity <= 1)) {
    summary.issues.push(`validator ${m.severity === 0 ? 'error' : 'warning'} ${m.code} at ${m.pointer ?? m.offset}: ${m.message}`);
  }
}

function parse(bytes, file) {
  const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
  const dir = file.includes('/') ? file.slice(0, file.lastIndexOf('/') + 1) : './';
  const loader = new GLTFLoader();
  const text = new TextDecoder().decode(bytes.subarray(0, 4));
  if (text !== 'glTF') {
    // A .gltf with external buffers: inline them as data URIs so no fetch is needed.
    const json = JSON.parse(new TextDecoder().decode(bytes));
    for (const b of json.buffers ?? []) {
      if (b.uri && !b.uri.startsWith('data:')) {
        b.uri = 'data:application/octet-stream;base64,' + readFileSync(dir + decodeURIComponent(b.uri)).toString('base64');
      }
    }
    return new Promise((resolve, reject) => loader.parse(JSON.stringify(json), '', resolve, reject));
  }
  return new Promise((resolve, reject) => loader.parse(buffer, '', resolve, reject));
}

function diagonal(frames) {
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (const f of frames) for (const p of f) for (let d = 0; d < 3; d++) {
    lo[d] = Math.min(lo[d], p[d]);
    hi[d] = Math.max(hi[d], p[d]);
  }
  return Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
}

async function main() {
  const [file, expectedPath] = process.argv.slice(2);
  if (!file || !expectedPath) {
    console.error('usage: node gltf_cache_check.mjs FILE.glb EXPECTED.json');
    return 2;
  }
  const bytes = new Uint8Array(readFileSync(file));
  const expected = JSON.parse(readFileSync(expectedPath, 'utf8'));
  const tolerance = expected.tolerance ?? 1e-5;
  const summary = { file, issues: [] };
  await validate(bytes, file, summary);

  const gltf = await parse(bytes, file);
  const clips = expected.animation == null ? gltf.animations : gltf.animations.filter((c) => c.name === expected.animation);
  if (clips.length !== 1) {
    summary.issues.push(`expected one animation named ${expected.animation}, three.js found ${clips.length} (of ${gltf.animations.map((c) => c.name)})`);
    return finish(summary);
  }
  const meshes = [];
  gltf.scene.traverse((o) => o.isMesh && meshes.push(o));
  summary.meshes = meshes.length;
  summary.skinned = meshes.some((m) => m.isSkinnedMesh);
  const mixer = new THREE.AnimationMixer(gltf.scene);
  const action = mixer.clipAction(clips[0]);
  action.setLoop(THREE.LoopOnce);
  action.clampWhenFinished = true;
  action.play();

  const scale = Math.max(diagonal(expected.points), 1e-30);
  const v = new THREE.Vector3();
  let worst = 0;
  let worstTime = null;
  expected.times.forEach((t, i) => {
    action.reset();
    mixer.setTime(t);
    gltf.scene.updateMatrixWorld(true);
    const got = [];
    for (const mesh of meshes) {
      const count = mesh.geometry.attributes.position.count;
      for (let k = 0; k < count; k++) {
        mesh.getVertexPosition(k, v);
        v.applyMatrix4(mesh.matrixWorld);
        got.push([v.x, v.y, v.z]);
      }
    }
    const want = expected.points[i];
    if (got.length !== want.length) {
      summary.issues.push(`time ${t}: three.js has ${got.length} points, expected ${want.length}`);
      return;
    }
    let error = 0;
    for (let k = 0; k < got.length; k++) error = Math.max(error, Math.hypot(got[k][0] - want[k][0], got[k][1] - want[k][1], got[k][2] - want[k][2]));
    error /= scale;
    if (error > worst) [worst, worstTime] = [error, t];
  });
  Object.assign(summary, { times: expected.times.length, max_error: worst, worst_time: worstTime });
  if (worst > tolerance) summary.issues.push(`max error ${worst.toPrecision(3)} (relative to the bbox diagonal) at ${worstTime} s exceeds ${tolerance}`);
  return finish(summary);
}

function finish(summary) {
  summary.ok = summary.issues.length === 0;
  for (const issue of summary.issues) console.error(`${summary.file}: ${issue}`);
  console.log(JSON.stringify(summary));
  return summary.ok ? 0 : 1;
}

main().then(
  (code) => process.exit(code),
  (e) => {
    console.error(e?.stack ?? String(e));
    console.log(JSON.stringify({ ok: false, issues: [String(e)] }));
    process.exit(1);
  },
);
