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
import * as THREE from 'three';
import { compare, finish, parse, play, run, validate } from './gltf_eval.mjs';

async function main() {
  const [file, expectedPath] = process.argv.slice(2);
  if (!file || !expectedPath) {
    console.error('usage: node gltf_cache_check.mjs FILE.glb EXPECTED.json');
    return 2;
  }
  const bytes = new Uint8Array(readFileSync(file));
  const expected = JSON.parse(readFileSync(expectedPath, 'utf8'));
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
  const v = new THREE.Vector3();
  compare(expected, summary, play(gltf.scene, clips), (_, i) => {
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
    return [got, expected.points[i]];
  });
  return finish(summary);
}

run(main);
