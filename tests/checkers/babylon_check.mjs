#!/usr/bin/env node
// Check a .glb written by blendsim with Babylon.js, a second engine independent of three.js.
//
// usage: node babylon_check.mjs FILE.glb EXPECTED.json
//
// Babylon.js (npm @babylonjs/core + @babylonjs/loaders) in plain Node with a NullEngine:
// LoadAssetContainerAsync on the glb bytes, the animation group paused, and for each EXPECTED
// time goToFrame(t x its frame rate), then the mesh's CPU-morphed positions
// (getPositionData(false, true): KHR_mesh_quantization integers as Babylon reads them) moved by
// the mesh's transform below the loader's `__root__` (which only changes handedness), i.e. the
// glTF node transform that also undoes the quantization grid, and mapped back to scene units by
// the placement EXPECTED gives (up_axis, meters_per_unit). The largest distance to the EXPECTED
// points over their bounding-box diagonal must be <= tolerance. Files that require
// EXT_meshopt_compression are not loaded here: Babylon fetches its meshopt decoder from a CDN.
//
// Prints issues to stderr and a one-line JSON summary to stdout; exit 0 when everything passes.

import { readFileSync } from 'node:fs';
import { Logger, NullEngine, Scene, LoadAssetContainerAsync, Matrix, Vector3 } from '@babylonjs/core/index.js';
import '@babylonjs/loaders/glTF/index.js';
import { compare, finish, run } from './gltf_eval.mjs';

/** The matrix taking scene units to glTF's y-up meters (see gltf_check.mjs). */
function placement(expected) {
  const s = expected.meters_per_unit ?? 1;
  const m = Matrix.Scaling(s, s, s);
  return (expected.up_axis ?? 'y') === 'z' ? Matrix.RotationX(-Math.PI / 2).multiply(m) : m;
}

async function main() {
  const [file, expectedPath] = process.argv.slice(2);
  if (!file || !expectedPath) {
    console.error('usage: node babylon_check.mjs FILE.glb EXPECTED.json');
    return 2;
  }
  Logger.LogLevels = Logger.ErrorLogLevel;
  const bytes = new Uint8Array(readFileSync(file));
  const expected = JSON.parse(readFileSync(expectedPath, 'utf8'));
  const summary = { file, issues: [], babylon: '9.35' };
  const scene = new Scene(new NullEngine());
  const container = await LoadAssetContainerAsync(bytes, scene, { pluginExtension: '.glb' });
  container.addAllToScene();
  const root = container.meshes.find((m) => m.name === '__root__');
  const meshes = container.meshes.filter((m) => m.getTotalVertices() > 0);
  if (meshes.length < 1) {
    summary.issues.push('Babylon.js found no mesh with vertices');
    return finish(summary);
  }
  const mesh = meshes[0];
  summary.vertices = mesh.getTotalVertices();
  summary.targets = mesh.morphTargetManager?.numTargets ?? 0;
  const group = container.animationGroups[0];
  const fps = group?.targetedAnimations[0]?.animation.framePerSecond ?? 60;
  if (group) {
    group.start(false);
    group.pause();
  }
  const seamSources = JSON.parse(new TextDecoder().decode(bytes.subarray(20, 20 + new DataView(bytes.buffer, bytes.byteOffset).getUint32(12, true)))).meshes?.[0]?.extras?.seamSources ?? [];
  const toScene = Matrix.Invert(placement(expected));
  const mixer = { setTime: (t) => group?.goToFrame(t * fps) };
  compare(expected, summary, { mixer, actions: [] }, (t, i) => {
    root?.computeWorldMatrix(true);
    const node = mesh.computeWorldMatrix(true).multiply(Matrix.Invert(root ? root.getWorldMatrix() : Matrix.Identity()));
    const local = node.multiply(toScene);
    const data = mesh.getPositionData(false, true);
    const got = [];
    for (let v = 0; v < data.length / 3; v++) {
      got.push(Vector3.TransformCoordinates(new Vector3(data[3 * v], data[3 * v + 1], data[3 * v + 2]), local).asArray());
    }
    return [got, expected.points[i].concat(seamSources.map((j) => expected.points[i][j]))];
  });
  return finish(summary);
}

run(main);
