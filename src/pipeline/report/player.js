// blendsim report player: the blendshape animation (base + shapes x weights, evaluated here)
// beside its reference (positions per frame, int16 over their bounding box), drawn on two 2D
// canvases from one fixed viewpoint, coloured by the distance from the hermite baseline. All data
// is in the page (#player-data): nothing is fetched. window.blendsimPlayer exposes the state.
'use strict';
(() => {
  const data = JSON.parse(document.getElementById('player-data').textContent);
  const raw = (b64) => {
    const s = atob(b64);
    const b = new Uint8Array(s.length);
    for (let i = 0; i < s.length; i++) b[i] = s.charCodeAt(i);
    return new DataView(b.buffer);
  };
  const array = (b64, size, Kind, get) => {
    const v = raw(b64);
    const out = new Kind(v.byteLength / size);
    for (let i = 0; i < out.length; i++) out[i] = get(v, i * size);
    return out;
  };
  const f32 = (b) => array(b, 4, Float32Array, (v, o) => v.getFloat32(o, true));
  const u32 = (b) => array(b, 4, Uint32Array, (v, o) => v.getUint32(o, true));
  const i16 = (b) => array(b, 2, Int16Array, (v, o) => v.getInt16(o, true));
  const u8 = (b) => array(b, 1, Uint8Array, (v, o) => v.getUint8(o));

  const V = data.vertices;
  const F = data.times.length;
  const triangles = u32(data.triangles);
  const base = f32(data.base);
  const shapes = data.shapes.map((s) => ({ indices: u32(s.indices), offsets: f32(s.offsets) }));
  const weights = f32(data.weights);
  const quantized = i16(data.frames.positions);
  const origin = data.frames.origin;
  const step = data.frames.step;
  const distance = u8(data.distance.values);

  // Positions of frame f: the blendshape clip's and the reference's.
  const blendshape = (f) => {
    const out = Float64Array.from(base);
    shapes.forEach((s, j) => {
      const w = weights[f * shapes.length + j];
      if (w === 0) return;
      for (let k = 0; k < s.indices.length; k++) {
        const i = 3 * s.indices[k];
        out[i] += w * s.offsets[3 * k];
        out[i + 1] += w * s.offsets[3 * k + 1];
        out[i + 2] += w * s.offsets[3 * k + 2];
      }
    });
    return out;
  };
  const reference = (f) => {
    const out = new Float64Array(3 * V);
    for (let i = 0; i < 3 * V; i++) out[i] = origin[i % 3] + step * quantized[3 * V * f + i];
    return out;
  };

  // One viewpoint for both views: the reference's bounding box over every frame, turned a little.
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < quantized.length; i++) {
    const x = origin[i % 3] + step * quantized[i];
    lo[i % 3] = Math.min(lo[i % 3], x);
    hi[i % 3] = Math.max(hi[i % 3], x);
  }
  const centre = [0, 1, 2].map((d) => 0.5 * (lo[d] + hi[d]));
  const radius = Math.max(1e-12, 0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]));
  const yaw = 0.6;
  const pitch = 0.35;
  const project = (p, width, height) => {
    const scale = (0.48 * Math.min(width, height)) / radius;
    const out = new Float32Array(3 * V);
    for (let v = 0; v < V; v++) {
      const x = p[3 * v] - centre[0];
      const y = p[3 * v + 1] - centre[1];
      const z = p[3 * v + 2] - centre[2];
      const x1 = Math.cos(yaw) * x + Math.sin(yaw) * z;
      const z1 = -Math.sin(yaw) * x + Math.cos(yaw) * z;
      const y1 = Math.cos(pitch) * y - Math.sin(pitch) * z1;
      out[3 * v] = width / 2 + scale * x1;
      out[3 * v + 1] = height / 2 - scale * y1;
      out[3 * v + 2] = Math.sin(pitch) * y + Math.cos(pitch) * z1; // towards the viewer
    }
    return out;
  };
  // Blue (0) through yellow to red (the largest distance from the hermite baseline).
  const colour = (t, light) => {
    const stops = [[40, 90, 200], [240, 210, 60], [200, 40, 30]];
    const [a, b, u] = t < 0.5 ? [stops[0], stops[1], 2 * t] : [stops[1], stops[2], 2 * t - 1];
    const c = [0, 1, 2].map((d) => Math.round(light * (a[d] + (b[d] - a[d]) * Math.min(1, Math.max(0, u)))));
    return `rgb(${c[0]},${c[1]},${c[2]})`;
  };

  const draw = (canvas, positions, f) => {
    const g = canvas.getContext('2d');
    g.clearRect(0, 0, canvas.width, canvas.height);
    const s = project(positions, canvas.width, canvas.height);
    const d = (v) => distance[f * V + v] / 255;
    if (triangles.length > 0) {
      const order = [];
      for (let t = 0; t < triangles.length / 3; t++) order.push(t);
      const depth = (t) => s[3 * triangles[3 * t] + 2] + s[3 * triangles[3 * t + 1] + 2] + s[3 * triangles[3 * t + 2] + 2];
      order.sort((a, b) => depth(a) - depth(b) || a - b);
      for (const t of order) {
        const [i, j, k] = [triangles[3 * t], triangles[3 * t + 1], triangles[3 * t + 2]];
        const ax = s[3 * j] - s[3 * i], ay = s[3 * j + 1] - s[3 * i + 1];
        const bx = s[3 * k] - s[3 * i], by = s[3 * k + 1] - s[3 * i + 1];
        const area = Math.abs(ax * by - ay * bx);
        const edge = Math.max(1e-9, Math.hypot(ax, ay) * Math.hypot(bx, by));
        const fill = colour((d(i) + d(j) + d(k)) / 3, 0.55 + 0.45 * Math.min(1, area / edge));
        g.fillStyle = fill;
        g.strokeStyle = fill;
        g.beginPath();
        g.moveTo(s[3 * i], s[3 * i + 1]);
        g.lineTo(s[3 * j], s[3 * j + 1]);
        g.lineTo(s[3 * k], s[3 * k + 1]);
        g.closePath();
        g.fill();
        g.stroke();
      }
    } else {
      for (let v = 0; v < V; v++) {
        g.fillStyle = colour(d(v), 1);
        g.fillRect(s[3 * v] - 1.5, s[3 * v + 1] - 1.5, 3, 3);
      }
    }
    return s;
  };

  const views = { blendshape: document.getElementById('view-blendshape'), reference: document.getElementById('view-reference') };
  const scrub = document.getElementById('scrub');
  const time = document.getElementById('time');
  const timeline = document.getElementById('timeline');
  const t0 = data.times[0];
  const t1 = data.times[F - 1];
  const state = {
    frames: F,
    frame: 0,
    times: data.times,
    keyTimes: data.keyTimes,
    step,
    error: data.error,
    drawn: {},
    blendshape,
    reference,
    setFrame: null,
  };

  const drawTimeline = (f) => {
    const g = timeline.getContext('2d');
    const x = (t) => 4 + ((timeline.width - 8) * (t - t0)) / Math.max(1e-12, t1 - t0);
    g.clearRect(0, 0, timeline.width, timeline.height);
    g.fillStyle = '#ccc';
    g.fillRect(4, 11, timeline.width - 8, 2);
    g.fillStyle = '#c03';
    for (const t of data.keyTimes) g.fillRect(x(t) - 1, 2, 2, 20);
    g.fillStyle = '#0072b2';
    g.fillRect(x(data.times[f]) - 2, 6, 4, 12);
  };

  state.setFrame = (f) => {
    f = Math.max(0, Math.min(F - 1, Math.round(f)));
    state.frame = f;
    state.drawn.blendshape = draw(views.blendshape, blendshape(f), f);
    state.drawn.reference = draw(views.reference, reference(f), f);
    scrub.value = String(f);
    time.textContent = `${data.times[f].toFixed(3)} s`;
    drawTimeline(f);
  };
  scrub.addEventListener('input', () => state.setFrame(Number(scrub.value)));

  // Play in real time from the current frame; pressing again pauses.
  const play = document.getElementById('play');
  let playing = null;
  play.addEventListener('click', () => {
    if (playing !== null) {
      cancelAnimationFrame(playing);
      playing = null;
      play.textContent = 'play';
      return;
    }
    play.textContent = 'pause';
    const start = performance.now();
    const from = data.times[state.frame] >= t1 ? t0 : data.times[state.frame];
    const tick = (now) => {
      const t = from + (now - start) / 1000;
      let f = state.frame;
      while (f < F - 1 && data.times[f + 1] <= t) f++;
      if (f !== state.frame) state.setFrame(f);
      if (t >= t1) {
        playing = null;
        play.textContent = 'play';
        return;
      }
      playing = requestAnimationFrame(tick);
    };
    if (from === t0) state.setFrame(0);
    playing = requestAnimationFrame(tick);
  });

  window.blendsimPlayer = state;
  state.setFrame(0);
})();
