#!/usr/bin/env node
// Check a .glb written by blendsim with the Khronos glTF validator and three.js, independently
// of blendsim.
//
// usage: node gltf_check.mjs FILE.glb EXPECTED.json
//
// 1. gltf-validator validateBytes: zero errors AND zero warnings (a wrong animation channel
//    path is only a warning), every issue printed otherwise.
// 2. three.js GLTFLoader.parse (plain Node, no DOM; textures are not decoded; meshopt views
//    decoded by three's MeshoptDecoder) + AnimationMixer: for each EXPECTED time,
//    mixer.setTime(t), then the morphed positions on the CPU from the geometry's
//    morphAttributes (normalized integers as three reads them) and the mesh's
//    morphTargetInfluences (glTF targets are relative), moved by the node's world matrix (which
//    also undoes KHR_mesh_quantization's integer grid) and mapped back to scene units by the
//    placement EXPECTED gives. The largest distance to the EXPECTED points divided by their
//    bounding-box diagonal must be <= tolerance.
// 3. So the world matrix must map scene units to glTF's y-up meters: scale by meters_per_unit,
//    and rotate -90 degrees about X when up_axis is "z" (when EXPECTED says); a wrong placement
//    shows as a distance.
//
// EXPECTED.json is described in README.md. Prints issues to stderr and a one-line JSON summary
// to stdout; exit code 0 when everything passes, 1 otherwise.

import { readFileSync } from 'node:fs';
import * as THREE from 'three';
import { compare, finish, maxDistance, parse, play, run, validate } from './gltf_eval.mjs';

/** The kind of animation the file holds, from its JSON: full-frame files are LINEAR with one
 *  target per frame (`frame_N`); blendshape files are CUBICSPLINE, or LINEAR samples of the
 *  weights at every frame. */
function kindOf(json) {
  const samplers = (json.animations ?? []).flatMap((a) => a.samplers);
  if (samplers.length === 0) return 'static';
  const interpolations = new Set(samplers.map((s) => s.interpolation ?? 'LINEAR'));
  if (interpolations.size !== 1) return [...interpolations].join('+');
  const interpolation = [...interpolations][0];
  if (interpolation === 'CUBICSPLINE') return 'blendshape';
  if (interpolation !== 'LINEAR') return interpolation;
  const names = json.meshes?.[0]?.extras?.targetNames ?? [];
  return names.length > 0 && names.every((n) => /^frame_-?\d+$/.test(n)) ? 'full-frame' : 'blendshape';
}

/** Local positions of a morphed mesh at its current influences. */
function morphedPositions(mesh) {
  const g = mesh.geometry;
  const base = g.attributes.position;
  const morphs = g.morphAttributes.position ?? [];
  const influences = mesh.morphTargetInfluences ?? [];
  const out = [];
  for (let v = 0; v < base.count; v++) {
    const p = [base.getX(v), base.getY(v), base.getZ(v)];
    morphs.forEach((m, j) => {
      const w = influences[j];
      if (w === 0) return;
      p[0] += w * (g.morphTargetsRelative ? m.getX(v) : m.getX(v) - base.getX(v));
      p[1] += w * (g.morphTargetsRelative ? m.getY(v) : m.getY(v) - base.getY(v));
      p[2] += w * (g.morphTargetsRelative ? m.getZ(v) : m.getZ(v) - base.getZ(v));
    });
    out.push(p);
  }
  return out;
}

/** The world matrix a scene with this up axis and unit must get in glTF. */
function expectedWorld(expected) {
  const m = new THREE.Matrix4().makeScale(...Array(3).fill(expected.meters_per_unit ?? 1));
  if ((expected.up_axis ?? 'y') === 'z') m.multiply(new THREE.Matrix4().makeRotationX(-Math.PI / 2));
  return m;
}

async function main() {
  const [file, expectedPath] = process.argv.slice(2);
  if (!file || !expectedPath) {
    console.error('usage: node gltf_check.mjs FILE.glb EXPECTED.json');
    return 2;
  }
  const bytes = new Uint8Array(readFileSync(file));
  const expected = JSON.parse(readFileSync(expectedPath, 'utf8'));
  const summary = { file, issues: [] };
  await validate(bytes, file, summary);

  const gltf = await parse(bytes, file);
  const meshes = [];
  gltf.scene.traverse((o) => o.isMesh && meshes.push(o));
  // One glTF mesh; three.js makes one Mesh per primitive (one per material group), which must
  // share their vertices.
  if (meshes.length < 1 || meshes.some((m) => m.geometry.attributes.position.count !== meshes[0].geometry.attributes.position.count)) {
    summary.issues.push(`expected one mesh (primitives sharing their vertices), three.js found ${meshes.length} meshes with ${meshes.map((m) => m.geometry.attributes.position.count)} vertices`);
    return finish(summary);
  }
  const mesh = meshes[0];
  summary.primitives = meshes.length;
  summary.materials = meshes.map((m) => m.material.name);
  summary.attributes = Object.keys(mesh.geometry.attributes).sort();
  // Vertices split at UV/normal seams: the copies after the points show extras.seamSources.
  const seamSources = gltf.parser.json.meshes?.[0]?.extras?.seamSources ?? [];
  summary.seam_copies = seamSources.length;
  summary.kind = kindOf(gltf.parser.json);
  summary.interpolation = [...new Set((gltf.parser.json.animations ?? []).flatMap((a) => a.samplers.map((s) => s.interpolation ?? 'LINEAR')))].join('+');
  if (expected.kind && summary.kind !== expected.kind && !(summary.kind === 'static' && expected.kind === 'blendshape')) {
    summary.issues.push(`animates as ${summary.kind}, expected ${expected.kind}`);
  }
  summary.vertices = mesh.geometry.attributes.position.count;
  summary.targets = (mesh.geometry.morphAttributes.position ?? []).length;

  gltf.scene.updateMatrixWorld(true);
  summary.extensions = gltf.parser.json.extensionsUsed ?? [];
  // World space (meters, y up) back to scene units through the expected placement: what a
  // renderer shows, in the units of EXPECTED.
  const toScene = new THREE.Matrix4().copy(expectedWorld(expected)).invert().multiply(mesh.matrixWorld);
  const v = new THREE.Vector3();
  const placed = (points) => points.map((p) => v.set(...p).applyMatrix4(toScene).toArray());

  compare(expected, summary, play(gltf.scene, gltf.animations), (t, i) => {
    const gots = meshes.map((m) => placed(morphedPositions(m)));
    for (const other of gots.slice(1)) if (maxDistance(other, gots[0]) > 0) summary.issues.push(`time ${t}: primitives of one mesh morph differently`);
    return [gots[0], expected.points[i].concat(seamSources.map((j) => expected.points[i][j]))];
  });
  return finish(summary);
}

run(main);
