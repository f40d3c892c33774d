/*
 * flexmb viewer: plays a flexmb run in 3D in the browser.
 *
 * This script is embedded by crates/flexmb-results/src/view.rs into one self-contained HTML
 * page (viewer/template.html), after the three.js bundle (window.THREE and
 * window.OrbitControls, built by viewer/build.sh) and the run's data: a JSON object in the
 * script element "flexmb-data", whose format view.rs documents: the model's metadata, the snapshots' times and sensor values, and "channels" (quantized,
 * differenced along the frames, zlib-compressed, base64) for node positions and
 * orientations, joint points and beam section strains and forces.
 *
 * What it draws, per snapshot ("frame"): the display shapes fixed on their nodes (box,
 * cylinder along z, sphere, triangle mesh), body frames as RGB triads, beam elements as
 * tubes between their nodes (coloured by a chosen section quantity, with a colour bar over
 * the whole run's range), joints as small spheres, springs as coils, a ground grid and the
 * axes. The side panel plots a sensor with a cursor at the current frame.
 *
 * Playback: the slider picks a snapshot (no interpolation between snapshots). Playing moves
 * a clock through the run at the chosen speed: 1x is real time for a dynamic run, and every
 * load step in 10 s for a static one (whose load factor need not grow: arc-length runs turn
 * back). The sensor plot's abscissa is the time or the load factor.
 *
 * Deterministic entry (for tests and links): the page reads location.hash, e.g.
 * "#frame=12&paused" (a snapshot index, from 0) or "#t=0.5" (the snapshot nearest that time
 * or load factor), "paused" to stay still, and optionally "colour=M2" (beam colour: none, N,
 * V2, V3, T, M2, M3, eps, gamma2, gamma3, kappa1, kappa2, kappa3), "sensor=NAME", "up=z",
 * "seethrough" (bodies' surfaces see-through).
 * The frame is set through the slider, as a user would. Once that frame is drawn, the
 * document element gets data-ready="true" and, when the hash chose a frame, the document's
 * title becomes "flexmb ready".
 */
(function () {
  'use strict';

  const THREE = window.THREE;

  // ---------------------------------------------------------------------------------------
  // Small helpers

  const $ = (id) => document.getElementById(id);

  function clamp(x, lo, hi) {
    return Math.min(hi, Math.max(lo, x));
  }

  /** A number with `digits` significant digits, without trailing noise. */
  function fmt(x, digits = 4) {
    if (x === null || !Number.isFinite(x)) return '–';
    if (x === 0) return '0';
    const a = Math.abs(x);
    if (a >= 1e5 || a < 1e-3) return x.toExponential(digits - 1).replace('e+', 'e');
    return String(Number(x.toPrecision(digits)));
  }

  /** About `count` round tick values covering [lo, hi] (1, 2, 5 times a power of ten). */
  function niceTicks(lo, hi, count) {
    const span = hi - lo;
    if (!(span > 0)) return { step: 1, ticks: [lo] };
    const raw = span / Math.max(1, count);
    const mag = Math.pow(10, Math.floor(Math.log10(raw)));
    const step = [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= raw) || 10 * mag;
    const ticks = [];
    for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-9 * span; v += step) {
      ticks.push(Math.abs(v) < 1e-12 * step ? 0 : v);
    }
    return { step, ticks };
  }

  /** Tick labels with as many decimals as the tick step needs. */
  function tickLabel(v, step) {
    const a = Math.max(Math.abs(v), step);
    if (a >= 1e5 || a < 1e-3) return v.toExponential(1).replace('e+', 'e');
    const decimals = clamp(-Math.floor(Math.log10(step) + 1e-9), 0, 8);
    return v.toFixed(decimals);
  }

  /** A 1-2-5 value nearest `x` (on a log scale). */
  function roundToSeries(x) {
    const mag = Math.pow(10, Math.floor(Math.log10(x)));
    const candidates = [1, 2, 5, 10].map((m) => m * mag);
    return candidates.reduce((best, c) =>
      Math.abs(Math.log(c / x)) < Math.abs(Math.log(best / x)) ? c : best
    );
  }

  function srgb(rgb) {
    return new THREE.Color().setRGB(rgb[0], rgb[1], rgb[2], THREE.SRGBColorSpace);
  }

  // ---------------------------------------------------------------------------------------
  // Decoding the data

  async function inflate(base64) {
    const text = atob(base64);
    const bytes = new Uint8Array(text.length);
    for (let i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('deflate'));
    return new Uint8Array(await new Response(stream).arrayBuffer());
  }

  /** A channel as a Float32Array of frames x items x comps values. */
  async function decodeChannel(ch, frames) {
    const n = ch.items * ch.comps;
    const total = n * frames;
    const out = new Float32Array(total);
    if (total === 0) return out;
    const planes = await inflate(ch.data);
    const acc = new Int32Array(n);
    for (let f = 0; f < frames; f++) {
      const base = f * n;
      for (let j = 0; j < n; j++) {
        const i = base + j;
        const delta =
          planes[i] | (planes[total + i] << 8) | (planes[2 * total + i] << 16) | (planes[3 * total + i] << 24);
        acc[j] = (acc[j] + delta) | 0;
        const c = j % ch.comps;
        out[i] = ch.origin[c] + ch.step[c] * acc[j];
      }
    }
    return out;
  }

  async function decodeRun(data) {
    const frames = data.frames;
    const [position, orientation, jointPosition, strain, stress] = await Promise.all([
      decodeChannel(data.position, frames),
      decodeChannel(data.orientation, frames),
      decodeChannel(data.joint_position, frames),
      decodeChannel(data.strain, frames),
      decodeChannel(data.stress, frames),
    ]);
    // Quantized quaternions are normalized again.
    for (let i = 0; i < orientation.length; i += 4) {
      const n = Math.hypot(orientation[i], orientation[i + 1], orientation[i + 2], orientation[i + 3]) || 1;
      for (let c = 0; c < 4; c++) orientation[i + c] /= n;
    }
    const slot = new Int32Array(data.nodes.length).fill(-1);
    data.oriented.forEach((node, k) => (slot[node] = k));
    const shapes = [];
    for (const s of data.shapes) {
      const shape = Object.assign({}, s);
      if (s.kind === 'mesh' && s.vertices) {
        shape.vertexArray = new Float32Array((await inflate(s.vertices)).buffer);
        shape.triangleArray = new Uint32Array((await inflate(s.triangles)).buffer);
      }
      shapes.push(shape);
    }
    return {
      data,
      frames,
      at: data.at,
      nodes: data.nodes.length,
      position,
      orientation,
      oriented: data.oriented.length,
      slot,
      jointPosition,
      strain,
      stress,
      shapes,
    };
  }

  // ---------------------------------------------------------------------------------------
  // Colour maps

  // Diverging (signed quantities, symmetric range): blue, a steel grey at zero, red.
  const DIVERGING = ['#2f3fb8', '#5f86ec', '#9fbcf2', '#c3c5ca', '#f2b49a', '#e4694f', '#b0061f'];
  // Sequential (quantities of one sign): dark violet to yellow.
  const SEQUENTIAL = ['#440154', '#414487', '#2a788e', '#22a884', '#7ad151', '#fde725'];

  function makeMap(stops) {
    const colours = stops.map((h) => new THREE.Color(h)); // sRGB hex, kept as sRGB numbers
    const rgb = stops.map((h) => [parseInt(h.slice(1, 3), 16), parseInt(h.slice(3, 5), 16), parseInt(h.slice(5, 7), 16)]);
    return {
      stops: colours,
      /** sRGB components in [0, 1] at s in [0, 1]. */
      at(s, out) {
        const x = clamp(s, 0, 1) * (rgb.length - 1);
        const k = Math.min(rgb.length - 2, Math.floor(x));
        const u = x - k;
        for (let c = 0; c < 3; c++) out[c] = ((1 - u) * rgb[k][c] + u * rgb[k + 1][c]) / 255;
        return out;
      },
    };
  }

  // ---------------------------------------------------------------------------------------
  // Beam quantities

  const STRESS_NAMES = [
    ['N', 'axial force N', 'N'],
    ['V2', 'shear force V2', 'N'],
    ['V3', 'shear force V3', 'N'],
    ['T', 'torque T', 'N m'],
    ['M2', 'bending moment M2', 'N m'],
    ['M3', 'bending moment M3', 'N m'],
  ];
  const STRAIN_NAMES = [
    ['eps', 'axial strain ε', ''],
    ['gamma2', 'shear strain γ2', ''],
    ['gamma3', 'shear strain γ3', ''],
    ['kappa1', 'twist κ1', '1/m'],
    ['kappa2', 'curvature κ2', '1/m'],
    ['kappa3', 'curvature κ3', '1/m'],
  ];

  function beamQuantities(data) {
    const list = [{ key: 'none', label: 'none (member colours)' }];
    STRESS_NAMES.forEach(([key, label, unit], c) =>
      list.push({ key, label, unit, field: 'stress', comp: c, range: data.stress_range[c] })
    );
    STRAIN_NAMES.forEach(([key, label, unit], c) =>
      list.push({ key, label, unit, field: 'strain', comp: c, range: data.strain_range[c] })
    );
    return list;
  }

  const MEMBER_COLOURS = ['#7d8fa6', '#c28f5a', '#7fa37a', '#a07ab0', '#b77b7b', '#6fa3a8'];

  // ---------------------------------------------------------------------------------------
  // The viewer

  class Viewer {
    constructor(run) {
      this.run = run;
      const data = run.data;
      this.data = data;
      this.frame = 0;
      this.playing = false;
      this.clock = 0;
      this.lastTick = null;
      this.needsRender = true;
      this.readyPending = false;
      this.signalTitle = false;

      const lo = data.bounds.min;
      const hi = data.bounds.max;
      this.centre = new THREE.Vector3((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2);
      this.extent = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
      this.size = Math.max(Math.hypot(...this.extent), 1e-6);

      this.setupRenderer();
      this.setupScene();
      this.setupUi();
      this.setUp(this.defaultUp());
      this.fitView();
      this.showFrame(0);
      this.loop();
    }

    // --- three.js set-up ---------------------------------------------------------------

    setupRenderer() {
      const canvas = $('canvas');
      try {
        this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
      } catch (e) {
        throw new Error('WebGL is not available in this browser, so the 3D view cannot be drawn. (' + e.message + ')');
      }
      this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
      this.scene = new THREE.Scene();
      this.scene.background = new THREE.Color(0xe8ecf1);
      this.camera = new THREE.PerspectiveCamera(35, 1, this.size * 1e-3, this.size * 100);
      this.scene.add(this.camera);
      const resize = () => {
        const view = $('view');
        const w = Math.max(1, view.clientWidth);
        const h = Math.max(1, view.clientHeight);
        this.renderer.setSize(w, h, false);
        this.camera.aspect = w / h;
        this.camera.updateProjectionMatrix();
        // Until the user moves the camera, the view keeps framing the whole motion. A
        // resized canvas is blank: draw it again before the page is painted.
        if (this.controls && !this.userMoved) this.fitView();
        if (this.controls) this.render();
        else this.needsRender = true;
      };
      resize();
      new ResizeObserver(resize).observe($('view'));
    }

    setupScene() {
      const { data, run } = this;
      const scene = this.scene;

      // Light: a sky/ground fill, and a key light that follows the camera.
      scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8f99, 1.6));
      const key = new THREE.DirectionalLight(0xffffff, 2.2);
      key.position.set(-0.7, 1, 0.6);
      this.camera.add(key);
      this.camera.add(key.target);
      key.target.position.set(0, 0, -1);

      // Node groups: one per node with an orientation, holding its shapes and its triad.
      this.nodeGroups = new Map();
      const group = (node) => {
        if (!this.nodeGroups.has(node)) {
          const g = new THREE.Group();
          g.matrixAutoUpdate = true;
          scene.add(g);
          this.nodeGroups.set(node, g);
        }
        return this.nodeGroups.get(node);
      };

      this.shapeObjects = [];
      const reach = new Map();
      for (const s of run.shapes) {
        const object = makeShape(s);
        if (!object) continue;
        group(s.node).add(object);
        this.shapeObjects.push(object);
        const r = Math.max(...s.size) / 2 + Math.hypot(...s.position);
        reach.set(s.node, Math.max(reach.get(s.node) || 0, r));
      }

      this.triads = [];
      for (const b of data.bodies) {
        const length = reach.has(b.node) ? 0.75 * reach.get(b.node) : 0.04 * this.size;
        const triad = new THREE.AxesHelper(Math.max(length, 0.02 * this.size));
        triad.material.depthTest = false;
        triad.material.transparent = true;
        triad.renderOrder = 10;
        group(b.node).add(triad);
        this.triads.push(triad);
      }
      for (const s of data.springs) s.nodes.forEach((n) => n >= 0 && group(n));

      this.setupBeams();
      this.setupJoints();
      this.setupSprings();
    }

    setupBeams() {
      const { data } = this;
      const beams = data.beams;
      this.beamMesh = null;
      if (beams.length === 0) return;
      const material = new THREE.MeshStandardMaterial({ roughness: 0.5, metalness: 0.05 });
      const tube = new THREE.CylinderGeometry(1, 1, 1, 18, 1, true);
      this.beamMesh = new THREE.InstancedMesh(tube, material, beams.length);
      this.beamMesh.frustumCulled = false;
      // A sphere at each beam node closes the tubes at bends and at free ends.
      const nodeRadius = new Map();
      beams.forEach((b) => b.nodes.forEach((n) => nodeRadius.set(n, Math.max(nodeRadius.get(n) || 0, b.radius))));
      this.beamNodes = [...nodeRadius.keys()];
      this.beamNodeRadius = this.beamNodes.map((n) => nodeRadius.get(n));
      this.beamNodeElements = new Map(this.beamNodes.map((n) => [n, []]));
      beams.forEach((b, e) => b.nodes.forEach((n) => this.beamNodeElements.get(n).push(e)));
      const ball = new THREE.SphereGeometry(1, 18, 12);
      this.beamNodeMesh = new THREE.InstancedMesh(ball, material, this.beamNodes.length);
      this.beamNodeMesh.frustumCulled = false;
      this.beamGroup = new THREE.Group();
      this.beamGroup.add(this.beamMesh, this.beamNodeMesh);
      this.scene.add(this.beamGroup);
      // Member colours for "none".
      const members = [...new Set(beams.map((b) => b.member))];
      this.memberColour = beams.map((b) => {
        const hex = MEMBER_COLOURS[members.indexOf(b.member) % MEMBER_COLOURS.length];
        return [1, 3, 5].map((i) => parseInt(hex.slice(i, i + 2), 16) / 255);
      });
      this.elementColour = new Float32Array(3 * beams.length);
    }

    setupJoints() {
      const joints = this.data.joints;
      this.jointMesh = null;
      if (joints.length === 0) return;
      // A ball of about 1 % of the model, but no bigger than the bodies' middle dimension
      // (a long chain of small links) and bigger than the beams' tubes.
      let radius = 0.012 * this.size;
      const middles = this.data.shapes.map((s) => [...s.size].sort((a, b) => a - b)[1]).filter((d) => d > 0);
      if (middles.length) {
        middles.sort((a, b) => a - b);
        radius = Math.min(radius, 0.6 * middles[middles.length >> 1]);
      }
      const beamRadius = this.data.beams.reduce((m, b) => Math.max(m, b.radius), 0);
      this.jointRadius = Math.max(radius, 1.5 * beamRadius);
      const material = new THREE.MeshStandardMaterial({ color: 0xe2832f, roughness: 0.4, metalness: 0.1 });
      this.jointMesh = new THREE.InstancedMesh(new THREE.SphereGeometry(1, 16, 12), material, joints.length);
      this.jointMesh.frustumCulled = false;
      // Thin links from each joint's point to the origins of its nodes show what it holds.
      this.jointLinkEnds = [];
      joints.forEach((j, k) => j.nodes.forEach((n) => n >= 0 && this.jointLinkEnds.push([k, n])));
      const links = new THREE.BufferGeometry();
      links.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6 * this.jointLinkEnds.length), 3));
      this.jointLinks = new THREE.LineSegments(links, new THREE.LineBasicMaterial({ color: 0x7a6650 }));
      this.jointLinks.frustumCulled = false;
      this.jointGroup = new THREE.Group();
      this.jointGroup.add(this.jointMesh, this.jointLinks);
      this.scene.add(this.jointGroup);
    }

    setupSprings() {
      this.springLines = [];
      const material = new THREE.LineBasicMaterial({ color: 0x3d6b4f });
      for (let k = 0; k < this.data.springs.length; k++) {
        const points = new Float32Array(3 * SPRING_POINTS);
        const geometry = new THREE.BufferGeometry();
        geometry.setAttribute('position', new THREE.BufferAttribute(points, 3));
        const line = new THREE.Line(geometry, material);
        line.frustumCulled = false;
        this.scene.add(line);
        this.springLines.push(line);
      }
    }

    /** The ground grid (below the whole motion, across the up axis) and the axes. */
    setupHelpers() {
      if (this.helpers) {
        this.scene.remove(this.helpers);
        this.helpers.traverse((o) => {
          if (o.geometry) o.geometry.dispose();
          if (o.material) {
            if (o.material.map) o.material.map.dispose();
            o.material.dispose();
          }
        });
      }
      const helpers = new THREE.Group();
      const up = 'xyz'.indexOf(this.up);
      const a = (up + 1) % 3;
      const b = (up + 2) % 3;
      const lo = this.data.bounds.min;
      const span = Math.max(this.extent[a], this.extent[b], 0.25 * this.size);
      const spacing = roundToSeries(span / 8);
      const half = 0.5 * span + 1.5 * spacing;
      const ca = this.centre.getComponent(a);
      const cb = this.centre.getComponent(b);
      const a0 = Math.floor((ca - half) / spacing) * spacing;
      const a1 = Math.ceil((ca + half) / spacing) * spacing;
      const b0 = Math.floor((cb - half) / spacing) * spacing;
      const b1 = Math.ceil((cb + half) / spacing) * spacing;
      const level = lo[up] - 0.02 * this.size;
      this.gridSpacing = spacing;
      const minor = [];
      const major = [];
      const push = (list, pa, pb, qa, qb) => {
        const p = [0, 0, 0];
        const q = [0, 0, 0];
        p[a] = pa; p[b] = pb; p[up] = level;
        q[a] = qa; q[b] = qb; q[up] = level;
        list.push(...p, ...q);
      };
      for (let v = a0; v <= a1 + 1e-9 * spacing; v += spacing) {
        push(Math.abs(v) < 1e-9 * spacing ? major : minor, v, b0, v, b1);
      }
      for (let v = b0; v <= b1 + 1e-9 * spacing; v += spacing) {
        push(Math.abs(v) < 1e-9 * spacing ? major : minor, a0, v, a1, v);
      }
      const lines = (list, colour) => {
        const g = new THREE.BufferGeometry();
        g.setAttribute('position', new THREE.Float32BufferAttribute(list, 3));
        return new THREE.LineSegments(g, new THREE.LineBasicMaterial({ color: colour }));
      };
      helpers.add(lines(minor, 0xc3cad3));
      if (major.length) helpers.add(lines(major, 0x98a3b0));

      // Axes at the origin, with their letters.
      const length = roundToSeries(0.15 * this.size);
      const axes = new THREE.AxesHelper(length);
      helpers.add(axes);
      const colours = ['#d03a2f', '#2e9b45', '#2f62c8'];
      ['x', 'y', 'z'].forEach((name, i) => {
        const label = makeLabel(name, colours[i]);
        const p = [0, 0, 0];
        p[i] = 1.12 * length;
        label.position.set(...p);
        label.scale.setScalar(0.034); // of the view's height: the same size at any zoom
        helpers.add(label);
      });
      this.axesLength = length;
      helpers.visible = $('show-grid').checked;
      this.helpers = helpers;
      this.scene.add(helpers);
    }

    // --- camera --------------------------------------------------------------------------

    defaultUp() {
      // A model that stays in the x-y plane is seen as drawn on paper, y up; else z is up.
      const e = this.extent;
      const planar = e[2] < 0.05 * Math.max(e[0], e[1]);
      return planar ? 'y' : 'z';
    }

    setUp(axis) {
      this.up = axis;
      $('up').value = axis;
      this.camera.up.set(axis === 'x' ? 1 : 0, axis === 'y' ? 1 : 0, axis === 'z' ? 1 : 0);
      if (this.controls) this.controls.dispose();
      this.controls = new window.OrbitControls(this.camera, this.renderer.domElement);
      this.controls.enableDamping = true;
      this.controls.dampingFactor = 0.12;
      this.controls.addEventListener('change', () => (this.needsRender = true));
      this.controls.addEventListener('start', () => (this.userMoved = true));
      this.setupHelpers();
    }

    /** Frames the box of the whole motion, seen from the front, right and above. */
    fitView() {
      const back = {
        z: new THREE.Vector3(0.95, -1.6, 0.85),
        y: new THREE.Vector3(0.7, 0.55, 1.6),
        x: new THREE.Vector3(0.85, 0.95, 1.6),
      }[this.up].normalize();
      // The camera's right and up directions for that view.
      const right = new THREE.Vector3().crossVectors(this.camera.up, back).normalize();
      const up = new THREE.Vector3().crossVectors(back, right);
      const tanV = Math.tan(THREE.MathUtils.degToRad(this.camera.fov) / 2);
      const tanH = tanV * this.camera.aspect;
      // The nearest distance from the box's centre at which every corner of the box is in
      // view, with a margin.
      const lo = this.data.bounds.min;
      const hi = this.data.bounds.max;
      const corner = new THREE.Vector3();
      let distance = 0;
      for (let i = 0; i < 8; i++) {
        corner.set(i & 1 ? hi[0] : lo[0], i & 2 ? hi[1] : lo[1], i & 4 ? hi[2] : lo[2]).sub(this.centre);
        const depth = corner.dot(back);
        distance = Math.max(
          distance,
          depth + Math.abs(corner.dot(right)) / (0.9 * tanH),
          depth + Math.abs(corner.dot(up)) / (0.84 * tanV)
        );
      }
      distance = Math.max(distance, 0.05 * this.size);
      const radius = 0.5 * this.size;
      this.camera.position.copy(this.centre).addScaledVector(back, distance);
      this.camera.near = Math.max(distance * 1e-3, distance - 40 * radius);
      this.camera.far = distance + 60 * radius;
      this.camera.updateProjectionMatrix();
      this.controls.target.copy(this.centre);
      this.controls.maxDistance = 20 * distance + 10 * radius;
      this.controls.update();
      this.needsRender = true;
    }

    // --- user interface ------------------------------------------------------------------

    setupUi() {
      const { data, run } = this;
      const first = data.first === 'load_factor' ? 'load factor' : 'time';
      this.isTime = first === 'time';
      const last = run.frames - 1;
      // Playback runs along a track: the time, or for a static run (whose load factor may go
      // back and forth, as in an arc-length continuation) the snapshot number.
      this.track = this.isTime ? run.at : run.at.map((_, k) => k);
      const span = this.track[last] - this.track[0];
      const steps = [];
      for (let k = 1; k < run.frames; k++) {
        const step = Math.abs(run.at[k] - run.at[k - 1]);
        if (step > 0) steps.push(step);
      }
      steps.sort((x, y) => x - y);
      const typical = steps.length ? steps[steps.length >> 1] : 1;
      this.decimals = clamp(Math.ceil(-Math.log10(typical || 1)) + 1, 0, 8);

      // Header and about.
      const plural = (n, one, many) => `${n} ${n === 1 ? one : many}`;
      const facts = [data.analysis === 'static' ? 'static' : 'dynamic'];
      if (data.bodies.length) facts.push(plural(data.bodies.length, 'body', 'bodies'));
      if (data.beams.length) facts.push(plural(data.beams.length, 'beam element', 'beam elements'));
      if (data.joints.length) facts.push(plural(data.joints.length, 'joint', 'joints'));
      if (data.springs.length) facts.push(plural(data.springs.length, 'spring', 'springs'));
      facts.push(plural(data.snapshots, 'snapshot', 'snapshots'));
      $('facts').textContent = facts.join(' · ');
      const about = [];
      about.push(`${data.analysis} analysis on ${data.group}, ${plural(data.nodes.length, 'node', 'nodes')}.`);
      about.push(
        `${plural(data.snapshots, 'snapshot', 'snapshots')}, ${first} ${this.formatAt(run.at[0])} to ${this.formatAt(run.at[last])}${this.isTime ? ' s' : ''}.`
      );
      $('about').textContent = about.join(' ');
      if (data.frames < data.snapshots) {
        const p = document.createElement('p');
        p.className = 'note warn';
        p.textContent = `Subsampled: the run has ${data.snapshots} snapshots; this page shows ${data.frames} of them, evenly spread (first and last included).`;
        $('about').appendChild(p);
      }
      this.gridNote = document.createElement('p');
      this.gridNote.className = 'note';
      $('about').appendChild(this.gridNote);

      // Slider and playback.
      const slider = $('slider');
      slider.max = String(last);
      slider.addEventListener('input', () => {
        const k = parseInt(slider.value, 10);
        this.clock = this.track[k];
        this.showFrame(k);
      });
      $('play').addEventListener('click', () => (this.playing ? this.pause() : this.play()));
      $('fit').addEventListener('click', () => {
        this.userMoved = false;
        this.fitView();
      });
      document.addEventListener('keydown', (e) => {
        const tag = e.target && e.target.tagName;
        if (tag === 'SELECT' || (tag === 'INPUT' && e.target.type !== 'range')) return;
        if (e.key === ' ') {
          e.preventDefault();
          this.playing ? this.pause() : this.play();
        } else if ((e.key === 'ArrowRight' || e.key === 'ArrowLeft') && e.target !== slider) {
          e.preventDefault();
          this.pause();
          this.seek(this.frame + (e.key === 'ArrowRight' ? 1 : -1));
        }
      });

      // Speeds: 1-2-5 steps around the default, which plays the run in about 10 s (real
      // time for runs of 2 to 60 s; every load step in 10 s for a static run).
      const unit = this.isTime ? 1 : Math.max(1, last) / 10; // track units per second at 1x
      this.speedUnit = unit;
      const wanted = span > 0 ? span / 10 / unit : 1;
      const preferred = this.isTime && span >= 2 && span <= 60 ? 1 : roundToSeries(wanted);
      const speed = $('speed');
      for (let e = -2; e <= 2; e++) {
        for (const m of [1, 2, 5]) {
          const v = Number((preferred * m * Math.pow(10, e)).toPrecision(3));
          if (v < preferred / 100 || v > preferred * 100) continue;
          const o = document.createElement('option');
          o.value = String(v);
          o.textContent = `${fmt(v, 3)}×`;
          if (v === preferred) o.selected = true;
          speed.appendChild(o);
        }
      }
      speed.title = this.isTime ? '1× is real time' : '1× plays every load step in 10 s';

      // Display toggles.
      const toggle = (id, apply) => {
        const box = $(id);
        box.addEventListener('change', () => {
          apply(box.checked);
          this.needsRender = true;
        });
        apply(box.checked);
      };
      $('show-frames').checked = data.bodies.length > 0 && data.bodies.length <= 10;
      toggle('show-shapes', (on) => this.shapeObjects.forEach((o) => (o.visible = on)));
      toggle('see-through', (on) => this.shapeObjects.forEach((o) => seeThrough(o, on)));
      toggle('show-frames', (on) => this.triads.forEach((o) => (o.visible = on)));
      toggle('show-beams', (on) => this.beamGroup && (this.beamGroup.visible = on));
      toggle('show-joints', (on) => this.jointGroup && (this.jointGroup.visible = on));
      toggle('show-springs', (on) => this.springLines.forEach((o) => (o.visible = on)));
      toggle('show-grid', (on) => this.helpers && (this.helpers.visible = on));
      const disable = (id, none) => {
        if (none) $(id).closest('label').hidden = true;
      };
      disable('show-shapes', this.shapeObjects.length === 0);
      disable('see-through', this.shapeObjects.length === 0);
      disable('show-frames', data.bodies.length === 0);
      disable('show-beams', data.beams.length === 0);
      disable('show-joints', data.joints.length === 0);
      disable('show-springs', data.springs.length === 0);
      $('up').addEventListener('change', () => {
        this.setUp($('up').value);
        this.fitView();
        this.updateGridNote();
      });

      // Beam colour.
      this.quantities = beamQuantities(data);
      const colourBy = $('colour-by');
      for (const q of this.quantities) {
        const o = document.createElement('option');
        o.value = q.key;
        o.textContent = q.unit ? `${q.label} [${q.unit}]` : q.label;
        colourBy.appendChild(o);
      }
      colourBy.addEventListener('change', () => this.setColourBy(colourBy.value));
      if (data.beams.length === 0) {
        $('beam-section').hidden = true;
        this.setColourBy('none');
      } else {
        // A bending moment by default: the one that varies the most.
        const m2 = this.quantities.find((q) => q.key === 'M2');
        const m3 = this.quantities.find((q) => q.key === 'M3');
        const spread = (q) => Math.max(Math.abs(q.range[0]), Math.abs(q.range[1]));
        const best = spread(m3) > spread(m2) ? m3 : m2;
        this.setColourBy(spread(best) > 0 ? best.key : 'none');
      }

      // Sensor plot.
      const sensor = $('sensor');
      if (data.sensors.length === 0) {
        $('sensor-section').hidden = true;
      } else {
        data.sensors.forEach((s, k) => {
          const o = document.createElement('option');
          o.value = String(k);
          o.textContent = s.unit ? `${s.name} [${s.unit}]` : s.name;
          sensor.appendChild(o);
        });
        sensor.addEventListener('change', () => this.drawPlot());
        const plot = $('plot');
        const seekFromPlot = (e) => {
          if (!this.plotMap) return;
          const rect = plot.getBoundingClientRect();
          const at = this.plotMap.atOfX(e.clientX - rect.left);
          this.pause();
          this.seek(this.nearestFrame(at));
        };
        let dragging = false;
        plot.addEventListener('pointerdown', (e) => {
          dragging = true;
          plot.setPointerCapture(e.pointerId);
          seekFromPlot(e);
        });
        plot.addEventListener('pointermove', (e) => dragging && seekFromPlot(e));
        plot.addEventListener('pointerup', () => (dragging = false));
        new ResizeObserver(() => this.drawPlot()).observe(plot);
      }

      setupModes(data.modes);
      window.addEventListener('hashchange', () => this.applyHash());
    }

    updateGridNote() {
      this.gridNote.textContent = `Grid squares: ${fmt(this.gridSpacing, 3)} m; axes: ${fmt(this.axesLength, 3)} m long, at the origin.`;
    }

    formatAt(at) {
      return Number.isFinite(at) ? at.toFixed(this.decimals) : '–';
    }

    /** The first snapshot nearest `at` (a time or load factor). */
    nearestFrame(at) {
      const a = this.run.at;
      let best = 0;
      for (let k = 1; k < a.length; k++) if (Math.abs(a[k] - at) < Math.abs(a[best] - at)) best = k;
      return best;
    }

    /** Moves the slider to frame k, as a user would. */
    seek(k) {
      const slider = $('slider');
      slider.value = String(clamp(Math.round(k), 0, this.run.frames - 1));
      slider.dispatchEvent(new Event('input', { bubbles: true }));
    }

    play() {
      if (this.run.frames < 2) return;
      if (this.frame >= this.run.frames - 1) this.seek(0);
      this.playing = true;
      this.lastTick = null;
      $('play').textContent = '❚❚ Pause';
    }

    pause() {
      this.playing = false;
      $('play').textContent = '▶ Play';
    }

    /** Reads the hash (see the header comment); returns whether it chose a frame. */
    applyHash() {
      const params = new URLSearchParams(location.hash.replace(/^#/, ''));
      if (params.has('paused')) this.pause();
      if (params.has('up') && 'xyz'.includes(params.get('up')) && params.get('up').length === 1) {
        this.setUp(params.get('up'));
        this.fitView();
        this.updateGridNote();
      }
      if (params.has('seethrough')) {
        $('see-through').checked = true;
        $('see-through').dispatchEvent(new Event('change'));
      }
      if (params.has('colour') && this.quantities.some((q) => q.key === params.get('colour'))) {
        this.setColourBy(params.get('colour'));
      }
      if (params.has('sensor')) {
        const k = this.data.sensors.findIndex((s) => s.name === params.get('sensor'));
        if (k >= 0) {
          $('sensor').value = String(k);
          this.drawPlot();
        }
      }
      let frame = null;
      if (params.has('frame')) {
        const k = parseInt(params.get('frame'), 10);
        if (Number.isFinite(k)) frame = k;
      } else if (params.has('t')) {
        const t = parseFloat(params.get('t'));
        if (Number.isFinite(t)) frame = this.nearestFrame(t);
      }
      if (frame !== null) this.seek(frame);
      return frame !== null;
    }

    setColourBy(key) {
      this.colourBy = this.quantities.find((q) => q.key === key) || this.quantities[0];
      $('colour-by').value = this.colourBy.key;
      const q = this.colourBy;
      const bar = $('colourbar');
      if (q.key === 'none' || !this.beamMesh) {
        bar.hidden = true;
        $('beam-note').textContent = '';
      } else {
        let [lo, hi] = q.range;
        if (lo < 0 && hi > 0) {
          const m = Math.max(-lo, hi);
          [lo, hi] = [-m, m];
          this.colourMap = makeMap(DIVERGING);
        } else {
          this.colourMap = makeMap(SEQUENTIAL);
        }
        if (hi === lo) {
          hi = lo + 1;
        }
        this.colourRange = [lo, hi];
        bar.hidden = false;
        $('colourbar-name').textContent = q.unit ? `${q.label} [${q.unit}]` : q.label;
        $('colourbar-lo').textContent = fmt(lo, 3);
        $('colourbar-mid').textContent = fmt((lo + hi) / 2, 3);
        $('colourbar-hi').textContent = fmt(hi, 3);
        const canvas = $('colourbar-canvas');
        const ctx = canvas.getContext('2d');
        const image = ctx.createImageData(canvas.width, 1);
        const c = [0, 0, 0];
        for (let i = 0; i < canvas.width; i++) {
          this.colourMap.at(i / (canvas.width - 1), c);
          image.data.set([c[0] * 255, c[1] * 255, c[2] * 255, 255], 4 * i);
        }
        ctx.putImageData(image, 0, 0);
        $('beam-note').textContent =
          `Range over the whole run: ${fmt(q.range[0], 3)} to ${fmt(q.range[1], 3)}${q.unit ? ' ' + q.unit : ''}` +
          ' (section frame; one value per element).';
      }
      if (this.beamMesh) this.showFrame(this.frame);
    }

    // --- drawing a frame -----------------------------------------------------------------

    showFrame(k) {
      const run = this.run;
      this.frame = k;
      const P = run.position;
      const Q = run.orientation;
      const pos = (n, out) => out.set(P[3 * (k * run.nodes + n)], P[3 * (k * run.nodes + n) + 1], P[3 * (k * run.nodes + n) + 2]);
      const quat = (n, out) => {
        const i = 4 * (k * run.oriented + run.slot[n]);
        return out.set(Q[i + 1], Q[i + 2], Q[i + 3], Q[i]); // stored w, x, y, z
      };

      for (const [node, g] of this.nodeGroups) {
        pos(node, g.position);
        quat(node, g.quaternion);
      }

      if (this.beamMesh) this.drawBeams(k, pos);

      if (this.jointMesh) {
        const J = run.jointPosition;
        const m = new THREE.Matrix4();
        const nj = this.data.joints.length;
        for (let j = 0; j < nj; j++) {
          const i = 3 * (k * nj + j);
          m.makeScale(this.jointRadius, this.jointRadius, this.jointRadius).setPosition(J[i], J[i + 1], J[i + 2]);
          this.jointMesh.setMatrixAt(j, m);
        }
        this.jointMesh.instanceMatrix.needsUpdate = true;
        const ends = this.jointLinks.geometry.attributes.position;
        const p = new THREE.Vector3();
        this.jointLinkEnds.forEach(([j, n], i) => {
          const jp = 3 * (k * nj + j);
          ends.setXYZ(2 * i, J[jp], J[jp + 1], J[jp + 2]);
          pos(n, p);
          ends.setXYZ(2 * i + 1, p.x, p.y, p.z);
        });
        ends.needsUpdate = true;
      }

      if (this.springLines.length) this.drawSprings(pos, quat);

      // Readouts.
      const at = run.at[k];
      const unit = this.isTime ? ' s' : '';
      $('clock').innerHTML = '';
      $('clock').append(`${this.isTime ? 't' : 'λ'} = ${this.formatAt(at)}${unit}`);
      const small = document.createElement('small');
      small.textContent = this.isTime ? `snapshot ${k + 1} of ${run.frames}` : `load factor · step ${k + 1} of ${run.frames}`;
      $('clock').appendChild(small);
      $('frameinfo').textContent = `${k + 1} / ${run.frames}`;
      if ($('slider').value !== String(k)) $('slider').value = String(k);
      this.drawPlot();
      this.needsRender = true;
    }

    drawBeams(k, pos) {
      const run = this.run;
      const beams = this.data.beams;
      const a = new THREE.Vector3();
      const b = new THREE.Vector3();
      const axis = new THREE.Vector3();
      const yAxis = new THREE.Vector3(0, 1, 0);
      const q = new THREE.Quaternion();
      const s = new THREE.Vector3();
      const m = new THREE.Matrix4();
      const colour = new THREE.Color();
      const rgb = [0, 0, 0];
      const quantity = this.colourBy;
      const field = quantity.key === 'none' ? null : run[quantity.field];
      const [lo, hi] = this.colourRange || [0, 1];
      for (let e = 0; e < beams.length; e++) {
        pos(beams[e].nodes[0], a);
        pos(beams[e].nodes[1], b);
        axis.subVectors(b, a);
        const length = axis.length();
        if (length > 0) q.setFromUnitVectors(yAxis, axis.divideScalar(length));
        s.set(beams[e].radius, Math.max(length, 1e-12), beams[e].radius);
        m.compose(a.add(b).multiplyScalar(0.5), q, s);
        this.beamMesh.setMatrixAt(e, m);
        if (field) {
          const v = field[6 * (k * beams.length + e) + quantity.comp];
          this.colourMap.at((v - lo) / (hi - lo), rgb);
        } else {
          rgb[0] = this.memberColour[e][0];
          rgb[1] = this.memberColour[e][1];
          rgb[2] = this.memberColour[e][2];
        }
        this.elementColour.set(rgb, 3 * e);
        this.beamMesh.setColorAt(e, colour.setRGB(rgb[0], rgb[1], rgb[2], THREE.SRGBColorSpace));
      }
      // Node spheres: the mean colour of their elements.
      const nodes = this.beamNodes;
      for (let i = 0; i < nodes.length; i++) {
        const r = this.beamNodeRadius[i];
        pos(nodes[i], a);
        m.makeScale(r, r, r).setPosition(a);
        this.beamNodeMesh.setMatrixAt(i, m);
        const elements = this.beamNodeElements.get(nodes[i]);
        rgb[0] = rgb[1] = rgb[2] = 0;
        for (const e of elements) for (let c = 0; c < 3; c++) rgb[c] += this.elementColour[3 * e + c] / elements.length;
        this.beamNodeMesh.setColorAt(i, colour.setRGB(rgb[0], rgb[1], rgb[2], THREE.SRGBColorSpace));
      }
      for (const mesh of [this.beamMesh, this.beamNodeMesh]) {
        mesh.instanceMatrix.needsUpdate = true;
        mesh.instanceColor.needsUpdate = true;
      }
    }

    drawSprings(pos, quat) {
      const p = [new THREE.Vector3(), new THREE.Vector3()];
      const q = new THREE.Quaternion();
      this.data.springs.forEach((spring, k) => {
        for (let end = 0; end < 2; end++) {
          const n = spring.nodes[end];
          p[end].fromArray(spring.points[end]);
          if (n >= 0) {
            quat(n, q);
            p[end].applyQuaternion(q).add(pos(n, new THREE.Vector3()));
          }
        }
        coil(p[0], p[1], 0.012 * this.size, this.springLines[k].geometry.attributes.position);
      });
    }

    // --- sensor plot ---------------------------------------------------------------------

    drawPlot() {
      const data = this.data;
      if (!data.sensors.length) return;
      const canvas = $('plot');
      const w = canvas.clientWidth;
      const h = canvas.clientHeight;
      if (w === 0 || h === 0) return;
      const ratio = window.devicePixelRatio || 1;
      if (canvas.width !== Math.round(w * ratio) || canvas.height !== Math.round(h * ratio)) {
        canvas.width = Math.round(w * ratio);
        canvas.height = Math.round(h * ratio);
      }
      const ctx = canvas.getContext('2d');
      ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
      ctx.clearRect(0, 0, w, h);

      const sensor = data.sensors[parseInt($('sensor').value, 10) || 0];
      const values = sensor.values;
      const at = this.run.at;
      let lo = Infinity;
      let hi = -Infinity;
      for (const v of values) {
        if (v !== null && Number.isFinite(v)) {
          lo = Math.min(lo, v);
          hi = Math.max(hi, v);
        }
      }
      if (!(lo <= hi)) {
        lo = -1;
        hi = 1;
      }
      if (hi - lo <= 1e-12 * Math.max(Math.abs(lo), Math.abs(hi), 1e-300)) {
        const pad = Math.abs(lo) > 0 ? 1e-3 * Math.abs(lo) : 1;
        lo -= pad;
        hi += pad;
      } else {
        const pad = 0.06 * (hi - lo);
        lo -= pad;
        hi += pad;
      }
      // The abscissa spans the run's times or load factors (which need not grow).
      let t0 = Math.min(...at);
      let t1 = Math.max(...at);
      if (!(t1 > t0)) {
        t0 -= 0.5;
        t1 += 0.5;
      }

      const yTicks = niceTicks(lo, hi, 4);
      ctx.font = '10px system-ui, sans-serif';
      const labels = yTicks.ticks.map((v) => tickLabel(v, yTicks.step));
      const left = Math.ceil(Math.max(...labels.map((s) => ctx.measureText(s).width), 10)) + 8;
      const box = { left, right: w - 14, top: 16, bottom: h - 30 };
      const x = (t) => box.left + ((t - t0) / (t1 - t0)) * (box.right - box.left);
      const y = (v) => box.bottom - ((v - lo) / (hi - lo)) * (box.bottom - box.top);
      this.plotMap = { atOfX: (px) => t0 + ((px - box.left) / (box.right - box.left)) * (t1 - t0) };

      // Frame, grid and ticks.
      ctx.strokeStyle = '#e3e7ec';
      ctx.lineWidth = 1;
      ctx.fillStyle = '#5f6b7a';
      ctx.textAlign = 'right';
      ctx.textBaseline = 'middle';
      yTicks.ticks.forEach((v, i) => {
        const py = Math.round(y(v)) + 0.5;
        ctx.beginPath();
        ctx.moveTo(box.left, py);
        ctx.lineTo(box.right, py);
        ctx.stroke();
        ctx.fillText(labels[i], box.left - 4, py);
      });
      const xTicks = niceTicks(t0, t1, 4);
      ctx.textAlign = 'center';
      ctx.textBaseline = 'top';
      for (const t of xTicks.ticks) {
        const px = Math.round(x(t)) + 0.5;
        ctx.beginPath();
        ctx.moveTo(px, box.top);
        ctx.lineTo(px, box.bottom);
        ctx.stroke();
        ctx.fillText(tickLabel(t, xTicks.step), px, box.bottom + 3);
      }
      ctx.strokeStyle = '#aab3be';
      ctx.strokeRect(box.left + 0.5, box.top + 0.5, box.right - box.left, box.bottom - box.top);
      ctx.fillText(this.isTime ? 'time [s]' : 'load factor', (box.left + box.right) / 2, box.bottom + 15);
      ctx.textAlign = 'left';
      ctx.textBaseline = 'bottom';
      ctx.fillText(sensor.unit ? `${sensor.name} [${sensor.unit}]` : sensor.name, box.left, box.top - 3);

      // The curve (gaps where a value is missing).
      ctx.save();
      ctx.beginPath();
      ctx.rect(box.left, box.top - 2, box.right - box.left, box.bottom - box.top + 4);
      ctx.clip();
      ctx.strokeStyle = '#2f6fb0';
      ctx.lineWidth = 1.6;
      ctx.beginPath();
      let pen = false;
      for (let k = 0; k < values.length; k++) {
        const v = values[k];
        if (v === null || !Number.isFinite(v)) {
          pen = false;
          continue;
        }
        if (pen) ctx.lineTo(x(at[k]), y(v));
        else ctx.moveTo(x(at[k]), y(v));
        pen = true;
      }
      ctx.stroke();
      ctx.restore();

      // The cursor at the current frame.
      const k = this.frame;
      const cx = Math.round(x(at[k])) + 0.5;
      ctx.strokeStyle = '#d2452f';
      ctx.lineWidth = 1.2;
      ctx.beginPath();
      ctx.moveTo(cx, box.top);
      ctx.lineTo(cx, box.bottom);
      ctx.stroke();
      const v = values[k];
      if (v !== null && Number.isFinite(v)) {
        ctx.fillStyle = '#d2452f';
        ctx.beginPath();
        ctx.arc(cx, y(v), 3.2, 0, 2 * Math.PI);
        ctx.fill();
      }
      $('readout').textContent =
        `${sensor.name} = ${fmt(v, 8)}${sensor.unit ? ' ' + sensor.unit : ''} at ${this.isTime ? 't' : 'λ'} = ${this.formatAt(at[k])}${this.isTime ? ' s' : ''}`;
    }

    // --- the loop --------------------------------------------------------------------------

    loop() {
      const tick = (now) => {
        if (this.playing) {
          const run = this.run;
          if (this.lastTick !== null) {
            const dt = Math.min(0.25, (now - this.lastTick) / 1000);
            this.clock += dt * parseFloat($('speed').value) * this.speedUnit;
          }
          this.lastTick = now;
          const track = this.track;
          const end = track[run.frames - 1];
          if (this.clock > end) {
            if ($('loop').checked) {
              this.clock = track[0] + ((this.clock - track[0]) % Math.max(end - track[0], 1e-300));
            } else {
              this.clock = end;
              this.pause();
            }
          }
          let k = this.frame;
          if (track[k] > this.clock) k = 0;
          while (k + 1 < run.frames && track[k + 1] <= this.clock) k++;
          if (k !== this.frame) this.showFrame(k);
        }
        if (this.controls.update()) this.needsRender = true;
        if (this.needsRender) this.render();
        requestAnimationFrame(tick);
      };
      requestAnimationFrame(tick);
    }

    render() {
      this.renderer.render(this.scene, this.camera);
      this.needsRender = false;
      if (this.readyPending) {
        this.readyPending = false;
        document.documentElement.dataset.ready = 'true';
        if (this.signalTitle) document.title = 'flexmb ready';
      }
    }
  }

  // ---------------------------------------------------------------------------------------
  // Geometry

  /** A display shape as a three.js object placed in its node's frame. */
  function makeShape(s) {
    let geometry;
    const [a, b, c] = s.size;
    switch (s.kind) {
      case 'box':
        geometry = new THREE.BoxGeometry(a, b, c);
        break;
      case 'cylinder':
        geometry = new THREE.CylinderGeometry(a / 2, a / 2, c, 40);
        geometry.rotateX(Math.PI / 2); // three.js cylinders run along y; ours along z
        break;
      case 'sphere':
        geometry = new THREE.SphereGeometry(a / 2, 40, 24);
        break;
      case 'mesh': {
        if (!s.vertexArray || s.triangleArray.length === 0) return null;
        const indexed = new THREE.BufferGeometry();
        indexed.setAttribute('position', new THREE.BufferAttribute(s.vertexArray, 3));
        indexed.setIndex(new THREE.BufferAttribute(s.triangleArray, 1));
        geometry = indexed.toNonIndexed(); // flat facets, as CAD meshes look
        geometry.computeVertexNormals();
        break;
      }
      default:
        return null;
    }
    const colour = srgb(s.colour);
    const material = new THREE.MeshStandardMaterial({
      color: colour,
      roughness: 0.55,
      metalness: 0.05,
      polygonOffset: true,
      polygonOffsetFactor: 1,
      polygonOffsetUnits: 1,
    });
    const mesh = new THREE.Mesh(geometry, material);
    mesh.renderOrder = 1; // after the opaque objects, when see-through
    const object = new THREE.Group();
    object.add(mesh);
    if (s.kind === 'box' || s.kind === 'cylinder') {
      const edges = new THREE.LineSegments(
        new THREE.EdgesGeometry(geometry, 30),
        new THREE.LineBasicMaterial({ color: colour.clone().multiplyScalar(0.45) })
      );
      object.add(edges);
    }
    object.position.fromArray(s.position);
    const [w, x, y, z] = s.orientation;
    object.quaternion.set(x, y, z, w);
    return object;
  }

  /** Makes a shape's surfaces see-through (its edges stay), or opaque again. */
  function seeThrough(object, on) {
    object.traverse((o) => {
      if (o.isMesh) {
        o.material.transparent = on;
        o.material.opacity = on ? 0.3 : 1;
        o.material.depthWrite = !on;
        o.material.needsUpdate = true;
      }
    });
  }

  const SPRING_COILS = 10;
  const SPRING_POINTS = SPRING_COILS * 16 + 3;

  /** A coil from p to q into `attribute` (straight leads at both ends). */
  function coil(p, q, radius, attribute) {
    const axis = new THREE.Vector3().subVectors(q, p);
    const length = axis.length();
    const dir = length > 0 ? axis.clone().divideScalar(length) : new THREE.Vector3(0, 0, 1);
    const u = new THREE.Vector3(1, 0, 0);
    if (Math.abs(dir.x) > 0.9) u.set(0, 1, 0);
    u.cross(dir).normalize();
    const v = new THREE.Vector3().crossVectors(dir, u);
    const r = Math.min(radius, 0.15 * length);
    const point = new THREE.Vector3();
    const n = SPRING_POINTS - 1;
    for (let i = 0; i <= n; i++) {
      let s = i / n;
      let rr = r;
      if (i === 0 || i === n) rr = 0; // leads on the axis
      const phase = 2 * Math.PI * SPRING_COILS * s;
      s = 0.08 + 0.84 * s;
      if (i === 0) s = 0;
      if (i === n) s = 1;
      point.copy(p).addScaledVector(dir, s * length).addScaledVector(u, rr * Math.cos(phase)).addScaledVector(v, rr * Math.sin(phase));
      attribute.setXYZ(i, point.x, point.y, point.z);
    }
    attribute.needsUpdate = true;
  }

  /** A letter that always faces the camera. */
  function makeLabel(text, colour) {
    const canvas = document.createElement('canvas');
    canvas.width = canvas.height = 64;
    const ctx = canvas.getContext('2d');
    ctx.font = 'bold 44px system-ui, sans-serif';
    ctx.fillStyle = colour;
    ctx.textAlign = 'center';
    ctx.textBaseline = 'middle';
    ctx.fillText(text, 32, 34);
    const texture = new THREE.CanvasTexture(canvas);
    texture.colorSpace = THREE.SRGBColorSpace;
    const material = new THREE.SpriteMaterial({ map: texture, depthTest: false, transparent: true, sizeAttenuation: false });
    return new THREE.Sprite(material);
  }

  // ---------------------------------------------------------------------------------------
  // Mode shapes

  /**
   * Hook for mode shapes. flexmb has no modal analysis yet, and view.rs writes an empty
   * "modes" list. When it has one, each entry is expected to carry a name, a frequency [Hz]
   * and per-node displacements (a channel like "position", one frame per mode); this is
   * where the "Mode shapes" panel gets its entries, and picking one would animate the
   * displaced configuration around the current frame. With no modes the panel stays hidden.
   */
  function setupModes(modes) {
    if (!Array.isArray(modes) || modes.length === 0) return;
    const select = $('mode');
    modes.forEach((m, k) => {
      const o = document.createElement('option');
      o.value = String(k);
      o.textContent = m.frequency !== undefined ? `${m.name || 'mode ' + (k + 1)} (${fmt(m.frequency, 4)} Hz)` : m.name || `mode ${k + 1}`;
      select.appendChild(o);
    });
    $('mode-section').hidden = false;
  }

  // ---------------------------------------------------------------------------------------
  // Start

  function showMessage(text) {
    const box = $('message');
    box.textContent = text;
    box.hidden = false;
    document.documentElement.dataset.ready = 'error';
  }

  async function start() {
    if (!THREE || !window.OrbitControls) throw new Error('three.js did not load: this page is damaged.');
    if (typeof DecompressionStream === 'undefined') {
      throw new Error('This browser cannot unpack the data (no DecompressionStream): open the page in a current Chrome, Edge, Firefox or Safari.');
    }
    const data = JSON.parse($('flexmb-data').textContent);
    const run = await decodeRun(data);
    const viewer = new Viewer(run);
    viewer.updateGridNote();
    window.flexmbViewer = viewer; // for the browser console
    const chose = viewer.applyHash();
    viewer.signalTitle = chose;
    viewer.readyPending = true;
    viewer.needsRender = true;
    if (!new URLSearchParams(location.hash.replace(/^#/, '')).has('paused')) viewer.play();
  }

  start().catch((e) => {
    console.error(e);
    showMessage(e && e.message ? e.message : String(e));
  });
})();
