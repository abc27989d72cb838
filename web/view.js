// SPDX-License-Identifier: BSD-3-Clause
// spheretouch live view: draws what the run's /ws stream says (src/spheretouch/view/view_server.hpp has the
// message layouts). three.js r111 (Debian's libjs-three) as the global THREE.
(function () {
  'use strict';
  const params = new URLSearchParams(location.search);
  const wantSnapshot = params.get('snapshot') === '1';
  const follow = params.get('follow') === '1';  // the camera follows the contact, closer in
  const statusEl = document.getElementById('status');
  const errorEl = document.getElementById('error');
  const plot = document.getElementById('plot');
  const plotCtx = plot.getContext('2d');

  const renderer = new THREE.WebGLRenderer({ antialias: false });
  renderer.setPixelRatio(1);
  renderer.setSize(window.innerWidth, window.innerHeight);
  renderer.setClearColor(0x15181c);
  document.getElementById('view').appendChild(renderer.domElement);
  const scene = new THREE.Scene();        // what moves: the probe, the red faces, the force arrow
  const stillScene = new THREE.Scene();   // what does not: the object
  const camera = new THREE.PerspectiveCamera(40, window.innerWidth / window.innerHeight, 0.1, 1e6);
  const controls = new THREE.OrbitControls(camera, renderer.domElement);
  scene.add(new THREE.AmbientLight(0xffffff, 0.35));
  const sun = new THREE.DirectionalLight(0xffffff, 0.75);
  camera.add(sun);
  sun.position.set(0.3, 0.6, 1);
  scene.add(camera);
  window.addEventListener('resize', () => {
    camera.aspect = window.innerWidth / window.innerHeight;
    camera.updateProjectionMatrix();
    renderer.setSize(window.innerWidth, window.innerHeight);
    still.key = '';
  });

  // The object does not move in its own frame: it is drawn into a texture (colour and depth) only
  // when the camera moves, and each frame composites that texture (writing its depth, so the probe
  // is hidden where the object is in front of it) and draws the probe and the overlays over it.
  // Software WebGL (SwiftShader: headless, or no GPU) pays per vertex, and the object is most of
  // the vertices (elephant 85,532 faces against hand_L2's 38,240). Without the two WebGL 1
  // extensions this needs, every frame draws the object.
  // ?cache=0 draws the object every frame (to measure what the cache saves).
  const still = { target: null, quad: null, key: '', draws: 0,
                  ok: params.get('cache') !== '0' && !!(renderer.extensions.get('WEBGL_depth_texture') &&
                                                          renderer.extensions.get('EXT_frag_depth')) };
  const quadCamera = new THREE.OrthographicCamera(-1, 1, 1, -1, 0, 1);
  const quadScene = new THREE.Scene();
  function stillTarget() {
    const size = renderer.getDrawingBufferSize(new THREE.Vector2());
    if (still.target && still.target.width === size.x && still.target.height === size.y) return still.target;
    if (still.target) still.target.dispose();
    const t = new THREE.WebGLRenderTarget(size.x, size.y, {
      minFilter: THREE.NearestFilter, magFilter: THREE.NearestFilter, format: THREE.RGBAFormat, stencilBuffer: false });
    t.texture.generateMipmaps = false;
    t.depthTexture = new THREE.DepthTexture(size.x, size.y);
    t.depthTexture.type = THREE.UnsignedIntType;
    if (!still.quad) {
      still.quad = new THREE.Mesh(new THREE.PlaneBufferGeometry(2, 2), new THREE.ShaderMaterial({
        uniforms: { tColor: { value: null }, tDepth: { value: null } },
        vertexShader: 'varying vec2 vUv; void main() { vUv = uv; gl_Position = vec4(position.xy, 0.0, 1.0); }',
        fragmentShader: 'uniform sampler2D tColor; uniform sampler2D tDepth; varying vec2 vUv;\n' +
          'void main() { gl_FragColor = texture2D(tColor, vUv); gl_FragDepthEXT = texture2D(tDepth, vUv).x; }',
        extensions: { fragDepth: true }, depthTest: true, depthWrite: true, depthFunc: THREE.AlwaysDepth }));
      still.quad.frustumCulled = false;
      quadScene.add(still.quad);
    }
    still.quad.material.uniforms.tColor.value = t.texture;
    still.quad.material.uniforms.tDepth.value = t.depthTexture;
    still.target = t;
    still.key = '';
    return t;
  }
  function draw() {
    renderer.autoClear = false;
    camera.updateMatrixWorld();
    if (!still.ok) {
      renderer.clear();
      renderer.render(stillScene, camera);
      renderer.render(scene, camera);
      return;
    }
    const t = stillTarget();
    const key = camera.matrixWorld.elements.join() + '|' + camera.projectionMatrix.elements.join();
    if (key !== still.key) {  // the camera moved (or the meshes came): the object again
      renderer.setRenderTarget(t);
      renderer.clear();
      renderer.render(stillScene, camera);
      renderer.setRenderTarget(null);
      still.key = key;
      ++still.draws;
    }
    renderer.clear();
    renderer.render(quadScene, quadCamera);
    renderer.render(scene, camera);
  }

  // Lighting baked into vertex colours (a fixed light over the object): software WebGL
  // (SwiftShader, headless or without a GPU) is bound by per-vertex work, and an unlit material
  // draws the elephant and the hand ~1.4x as fast as a lit one.
  const grey = new THREE.MeshBasicMaterial({ vertexColors: THREE.VertexColors });
  const blue = new THREE.MeshBasicMaterial({ vertexColors: THREE.VertexColors });
  const light = new THREE.Vector3(0.35, -0.55, 0.76).normalize();
  function bake(g, base) {
    const n = g.attributes.normal.array, c = new Float32Array(n.length);
    for (let i = 0; i < n.length; i += 3) {
      const k = 0.38 + 0.62 * Math.max(0, n[i] * light.x + n[i + 1] * light.y + n[i + 2] * light.z);
      c[i] = base[0] * k; c[i + 1] = base[1] * k; c[i + 2] = base[2] * k;
    }
    g.setAttribute('color', new THREE.BufferAttribute(c, 3));
  }
  // Colliding faces lie inside the other body, so they are drawn over everything (no depth test,
  // last): the contact patch stays in view whatever hides it.
  const red = new THREE.MeshBasicMaterial({ color: 0xff1a1a, side: THREE.DoubleSide, depthTest: false });

  // A body: its mesh (indexed, smooth-shaded), and a red overlay built from the colliding faces.
  function makeBody(vertices, faces, material, base) {
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(vertices, 3));
    g.setIndex(new THREE.BufferAttribute(faces, 1));
    g.computeVertexNormals();
    bake(g, base);
    const mesh = new THREE.Mesh(g, material);
    const hg = new THREE.BufferGeometry();
    const hpos = new THREE.BufferAttribute(new Float32Array(9 * 16384), 3);
    hpos.setUsage ? hpos.setUsage(THREE.DynamicDrawUsage) : (hpos.dynamic = true);
    hg.setAttribute('position', hpos);
    hg.setDrawRange(0, 0);
    const overlay = new THREE.Mesh(hg, red);
    overlay.frustumCulled = false;
    overlay.renderOrder = 10;
    const group = new THREE.Group();  // the probe moves as one; the object's parts go to two scenes
    group.add(mesh);
    group.add(overlay);
    return { vertices, faces, mesh, overlay, group, count: 0 };
  }
  function highlight(body, ids) {
    const pos = body.overlay.geometry.attributes.position;
    const n = Math.min(ids.length, pos.count / 3);
    const v = body.vertices, f = body.faces, out = pos.array;
    let k = 0;
    for (let i = 0; i < n; ++i) {
      const face = ids[i];
      if (3 * face + 2 >= f.length) continue;
      for (let j = 0; j < 3; ++j) {
        const a = 3 * f[3 * face + j];
        out[k++] = v[a]; out[k++] = v[a + 1]; out[k++] = v[a + 2];
      }
    }
    body.overlay.geometry.setDrawRange(0, k / 3);
    pos.updateRange.offset = 0;
    pos.updateRange.count = Math.max(k, 1);  // upload what is drawn, not the whole buffer
    pos.needsUpdate = true;
    body.count = k / 9;
  }

  let object = null, probe = null, objectOrigin = null, probeOrigin = null, radius = 100;
  const arrow = new THREE.ArrowHelper(new THREE.Vector3(0, 0, 1), new THREE.Vector3(), 1, 0xffd54f);
  arrow.visible = false;
  arrow.line.material.depthTest = false;  // the force at the contact, drawn over the bodies like the patch
  arrow.cone.material.depthTest = false;
  arrow.renderOrder = 11;
  arrow.line.renderOrder = 11;
  arrow.cone.renderOrder = 11;
  scene.add(arrow);
  // The proxy: where the probe would rest outside the object, the device's pose moved out by the
  // contact model's PD along FD (what the force pulls the hand towards). Drawn translucent while in
  // contact, sharing the probe's geometry.
  const ghost = new THREE.MeshBasicMaterial({ color: 0x9fd3ff, transparent: true, opacity: 0.35, depthWrite: false });
  let proxy = null;
  const forces = [];  // [t, |F|]
  let last = null, fresh = false, prevTicks = 0, prevRounds = 0, prevT = 0, hapticHz = 0, collisionHz = 0;
  let startedAt = performance.now(), textAt = 0, drawn = 0, fps = 0, fpsFrames = 0, fpsSince = performance.now(), snapshotSent = false, meshAt = 0;

  let others = [];  // a scene's other objects: meshes placed in the page's frame, drawn grey, no overlay
  function onMesh(buf) {
    const d = new DataView(buf);
    const version = d.getUint32(4, true);
    let o = 8;
    const f64 = () => { const x = d.getFloat64(o, true); o += 8; return x; };
    const u32 = () => { const x = d.getUint32(o, true); o += 4; return x; };
    objectOrigin = [f64(), f64(), f64()];
    probeOrigin = [f64(), f64(), f64()];
    const pnv = u32(), pnf = u32(), onv = u32(), onf = u32();
    const take = (Type, n) => { const a = new Type(buf.slice(o, o + 4 * n)); o += 4 * n; return a; };
    const pv = take(Float32Array, 3 * pnv), pf = take(Uint32Array, 3 * pnf);
    const ov = take(Float32Array, 3 * onv), of = take(Uint32Array, 3 * onf);
    // Version 2: the object's rotation in the world, and the scene's other objects, placed.
    let rot = null;
    const more = [];
    if (version >= 2) {
      rot = Array.from({ length: 9 }, f64);
      const n = u32();
      for (let i = 0; i < n; ++i) {
        const place = Array.from({ length: 12 }, f64);
        const nv = u32(), nf = u32();
        more.push({ place, v: take(Float32Array, 3 * nv), f: take(Uint32Array, 3 * nf) });
      }
    }
    for (const b of others) stillScene.remove(b.mesh), scene.remove(b.overlay);
    others = more.map((x) => {
      const b = makeBody(x.v, x.f, grey, [0.62, 0.66, 0.60]);
      const p = x.place;
      for (const part of [b.mesh, b.overlay]) {
        part.matrixAutoUpdate = false;
        part.matrix.set(p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8], p[9], p[10], p[11], 0, 0, 0, 1);
      }
      stillScene.add(b.mesh);
      scene.add(b.overlay);
      return b;
    });
    if (object) stillScene.remove(object.mesh), scene.remove(object.overlay);
    if (probe) scene.remove(probe.group), scene.remove(proxy);
    object = makeBody(ov, of, grey, [0.72, 0.70, 0.65]);
    probe = makeBody(pv, pf, blue, [0.50, 0.65, 0.85]);
    probe.group.matrixAutoUpdate = false;
    proxy = new THREE.Mesh(probe.mesh.geometry, ghost);
    proxy.matrixAutoUpdate = false;
    proxy.visible = false;
    scene.add(proxy);
    if (rot) {  // the object turned by its placement (its origin is the page's origin)
      for (const part of [object.mesh, object.overlay]) {
        part.matrixAutoUpdate = false;
        part.matrix.set(rot[0], rot[1], rot[2], 0, rot[3], rot[4], rot[5], 0, rot[6], rot[7], rot[8], 0, 0, 0, 0, 1);
      }
    }
    stillScene.add(object.mesh);
    scene.add(object.overlay);
    still.key = '';  // a new object: drawn again whatever the camera does
    scene.add(probe.group);
    object.mesh.geometry.computeBoundingSphere();
    const bs = object.mesh.geometry.boundingSphere;
    radius = bs.radius;
    camera.near = radius / 200;  // depth resolution where the bodies are, not over 0.1 mm .. 1 km
    camera.far = radius * 200;
    camera.updateProjectionMatrix();
    // From the front, a little above the object: a touch from above (the usual script) is seen
    // from the side, the red contact between the bodies in view.
    camera.position.set(bs.center.x + 1.9 * radius, bs.center.y - 2.8 * radius, bs.center.z + 0.9 * radius);
    camera.up.set(0, 0, 1);
    controls.target.copy(bs.center);
    controls.update();
    meshAt = performance.now();
  }

  function onFrame(buf) {
    const d = new DataView(buf);
    const f = (off) => d.getFloat64(off, true);
    const u64 = (off) => Number(d.getBigUint64(off, true));
    const fr = {
      flags: d.getUint32(4, true), round: u64(8),
      pose: Array.from({ length: 12 }, (_, i) => f(16 + 8 * i)),
      fd: [f(112), f(120), f(128)], cp: [f(136), f(144), f(152)],
      pd: f(160), roundMs: f(168), force: [f(176), f(184), f(192)],
      ticks: u64(200), misses: u64(208), rounds: u64(216), t: f(224),
      contacts: d.getUint32(232, true), np: d.getUint32(236, true), no: d.getUint32(240, true),
      torque: [f(248), f(256), f(264)],
    };
    const ids = new Uint32Array(buf.slice(272, 272 + 4 * (fr.np + fr.no)));
    fr.probeFaces = ids.subarray(0, fr.np);
    fr.objectFaces = ids.subarray(fr.np);
    if (prevT && fr.t > prevT + 0.25) {
      hapticHz = (fr.ticks - prevTicks) / (fr.t - prevT);
      collisionHz = (fr.rounds - prevRounds) / (fr.t - prevT);
      prevT = fr.t; prevTicks = fr.ticks; prevRounds = fr.rounds;
    } else if (!prevT) {
      prevT = fr.t; prevTicks = fr.ticks; prevRounds = fr.rounds;
    }
    const fmag = Math.hypot(fr.force[0], fr.force[1], fr.force[2]);
    forces.push([fr.t, fmag]);
    while (forces.length && forces[0][0] < fr.t - 5) forces.shift();
    last = fr;
    fresh = true;
  }

  function apply(fr) {
    if (!object) return;
    // Probe: object-local = T(-object origin) · pose · T(probe origin) · probe-local.
    const p = fr.pose;
    const m = new THREE.Matrix4().set(p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8], p[9], p[10], p[11], 0, 0, 0, 1);
    const pre = new THREE.Matrix4().makeTranslation(probeOrigin[0], probeOrigin[1], probeOrigin[2]);
    const post = new THREE.Matrix4().makeTranslation(-objectOrigin[0], -objectOrigin[1], -objectOrigin[2]);
    probe.group.matrix.copy(post.multiply(m).multiply(pre));
    probe.group.matrixWorldNeedsUpdate = true;
    proxy.visible = (fr.flags & 1) !== 0 && fr.pd > 0;
    if (proxy.visible) {
      const out = new THREE.Matrix4().makeTranslation(fr.pd * fr.fd[0], fr.pd * fr.fd[1], fr.pd * fr.fd[2]);
      proxy.matrix.copy(out.multiply(probe.group.matrix));
      proxy.matrixWorldNeedsUpdate = true;
    }
    // Object faces: the first object's ids, then each other object's offset by the faces before it.
    let from = 0, offset = 0;
    for (const b of [object, ...others]) {
      const n = b.faces.length / 3;
      let to = from;
      while (to < fr.objectFaces.length && fr.objectFaces[to] < offset + n) ++to;
      const ids = fr.objectFaces.subarray(from, to);
      if (ids.length || b.count) highlight(b, offset ? ids.map((id) => id - offset) : ids);  // idle bodies cost nothing
      from = to;
      offset += n;
    }
    highlight(probe, fr.probeFaces);
    const fmag = Math.hypot(fr.force[0], fr.force[1], fr.force[2]);
    if (follow && (fr.flags & 1)) {  // keep the camera's direction, centre the contact, 0.7 radii away
      // ... when it has left the middle of the view (a tenth of the distance off centre): a camera
      // that moved with every contact point would shake, and would redraw the object each frame.
      const c = new THREE.Vector3(fr.cp[0] - objectOrigin[0], fr.cp[1] - objectOrigin[1], fr.cp[2] - objectOrigin[2]);
      const closeIn = camera.position.distanceTo(controls.target) < 0.71 * radius;
      if (!closeIn || c.distanceTo(controls.target) > 0.07 * radius) {
        const dir = camera.position.clone().sub(controls.target).normalize();
        controls.target.copy(c);
        camera.position.copy(c).addScaledVector(dir, 0.7 * radius);
      }
    }
    if (fmag > 1e-3 && (fr.flags & 1)) {
      arrow.visible = true;
      arrow.position.set(fr.cp[0] - objectOrigin[0], fr.cp[1] - objectOrigin[1], fr.cp[2] - objectOrigin[2]);
      arrow.setDirection(new THREE.Vector3(fr.force[0] / fmag, fr.force[1] / fmag, fr.force[2] / fmag));
      const len = 0.15 * radius * Math.min(fmag, 5);
      arrow.setLength(len, 0.25 * len, 0.12 * len);
    } else {
      arrow.visible = false;
    }
    if (performance.now() - textAt < 200) return;  // text and plot 5 times a second: page layout is not free
    textAt = performance.now();
    drawPlot();
    statusEl.textContent =
      `t ${fr.t.toFixed(1)} s | haptic ${hapticHz.toFixed(0)} Hz, ${fr.misses} misses | ` +
      `collision ${collisionHz.toFixed(0)} Hz, ${fr.roundMs.toFixed(2)} ms | ${fr.contacts} contacts | ` +
      `PD ${fr.pd.toFixed(3)} mm | |F| ${fmag.toFixed(3)} N | ` +
      `|τ| ${(1000 * Math.hypot(fr.torque[0], fr.torque[1], fr.torque[2])).toFixed(1)} N·mm | view ${fps.toFixed(0)} fps` +
      (fr.flags & 2 ? ' | faces truncated' : '');
  }

  function drawPlot() {
    const w = plot.width, h = plot.height;
    plotCtx.clearRect(0, 0, w, h);
    plotCtx.fillStyle = '#8899aa';
    plotCtx.fillText('|F| N, last 5 s', 6, 12);
    if (forces.length < 2) return;
    const t1 = forces[forces.length - 1][0], t0 = t1 - 5;
    let fmax = 0.5;
    for (const [, v] of forces) fmax = Math.max(fmax, v);
    plotCtx.fillText(fmax.toFixed(2), w - 40, 12);
    plotCtx.strokeStyle = '#ffd54f';
    plotCtx.beginPath();
    forces.forEach(([t, v], i) => {
      const x = ((t - t0) / 5) * w, y = h - 4 - (v / fmax) * (h - 20);
      if (i) plotCtx.lineTo(x, y); else plotCtx.moveTo(x, y);
    });
    plotCtx.stroke();
  }

  // The browser device ([device] kind = "browser"): left-drag moves the tip in the horizontal
  // plane (as seen from the camera), the wheel (and PageUp/PageDown, Q/E) moves it up and down,
  // arrow keys/WASD step it, a gamepad's sticks move it; right-drag turns the view. The tip's pose
  // goes to the run at the page's frame rate; the run upsamples it to the servo's 1 kHz.
  const drive = { on: false, tip: null, dirty: false, sentAt: 0, seq: 0, drag: null, press: params.get('drive') };
  const mmPerWheel = 0.01;  // mm per wheel delta unit (a notch is ~100: 1 mm)
  function startDriving(home) {
    drive.on = true;
    drive.tip = home.slice();
    drive.dirty = true;
    controls.enableZoom = false;
    controls.mouseButtons = { LEFT: -1, MIDDLE: THREE.MOUSE.DOLLY, RIGHT: THREE.MOUSE.ROTATE };
    errorEl.textContent = '';
    statusEl.dataset.drive = '1';
  }
  function planeAxes() {  // camera right and forward, projected on the horizontal plane
    const f = new THREE.Vector3();
    camera.getWorldDirection(f);
    f.z = 0;
    if (f.lengthSq() < 1e-12) f.set(0, 1, 0);
    f.normalize();
    return { right: new THREE.Vector3(f.y, -f.x, 0), forward: f };
  }
  function moveTip(dx, dy, dz) {
    if (!drive.on) return;
    const v = [dx, dy, dz];
    if (!v.every(Number.isFinite)) return;  // never send a NaN
    for (let i = 0; i < 3; ++i) drive.tip[i] += v[i];
    drive.dirty = true;
  }
  const canvas = renderer.domElement;
  canvas.addEventListener('pointerdown', (e) => { if (drive.on && e.button === 0) drive.drag = [e.clientX, e.clientY]; });
  window.addEventListener('pointerup', () => { drive.drag = null; });
  window.addEventListener('pointermove', (e) => {
    if (!drive.drag) return;
    const dist = camera.position.distanceTo(controls.target);
    const mmPerPx = (2 * dist * Math.tan((camera.fov * Math.PI) / 360)) / canvas.clientHeight;
    const { right, forward } = planeAxes();
    const dx = (e.clientX - drive.drag[0]) * mmPerPx, dy = -(e.clientY - drive.drag[1]) * mmPerPx;
    drive.drag = [e.clientX, e.clientY];
    moveTip(right.x * dx + forward.x * dy, right.y * dx + forward.y * dy, 0);
  });
  canvas.addEventListener('wheel', (e) => {
    if (!drive.on) return;
    e.preventDefault();
    moveTip(0, 0, -e.deltaY * mmPerWheel * (e.shiftKey ? 0.1 : 1));
  }, { passive: false });
  window.addEventListener('keydown', (e) => {
    if (!drive.on) return;
    const step = e.shiftKey ? 0.1 : 1;  // mm
    const { right, forward } = planeAxes();
    const k = e.key;
    if (k === 'ArrowLeft' || k === 'a') moveTip(-right.x * step, -right.y * step, 0);
    else if (k === 'ArrowRight' || k === 'd') moveTip(right.x * step, right.y * step, 0);
    else if (k === 'ArrowUp' || k === 'w') moveTip(forward.x * step, forward.y * step, 0);
    else if (k === 'ArrowDown' || k === 's') moveTip(-forward.x * step, -forward.y * step, 0);
    else if (k === 'PageUp' || k === 'q') moveTip(0, 0, step);
    else if (k === 'PageDown' || k === 'e') moveTip(0, 0, -step);
    else return;
    e.preventDefault();
  });
  let padAt = 0;
  function pollGamepad(now) {
    const dt = padAt ? Math.min(0.1, (now - padAt) / 1000) : 0;
    padAt = now;
    if (!drive.on || !navigator.getGamepads) return;
    for (const pad of navigator.getGamepads()) {
      if (!pad || pad.axes.length < 2) continue;
      const ax = (i) => (i < pad.axes.length && Math.abs(pad.axes[i]) > 0.15 ? pad.axes[i] : 0);
      const speed = 20;  // mm/s at full deflection
      const { right, forward } = planeAxes();
      const x = ax(0) * speed * dt, y = -ax(1) * speed * dt, z = -ax(3) * speed * dt;
      if (x || y || z) moveTip(right.x * x + forward.x * y, right.y * x + forward.y * y, z);
      break;
    }
  }
  // ?drive=press: synthetic input for tests and demos: wheel events down until the contact shows,
  // then 3 mm more, as a hand would press.
  let pressedAfterContact = 0;
  function synthetic() {
    if (drive.press !== 'press' || !drive.on || !object) return;
    const inContact = last && (last.flags & 1);
    if (inContact) pressedAfterContact += 0.2;
    if (pressedAfterContact >= 3) return;
    canvas.dispatchEvent(new WheelEvent('wheel', { deltaY: 20, bubbles: true, cancelable: true }));
  }
  function sendPose(now) {
    if (!drive.on || !ws || ws.readyState !== 1) return;
    if (!drive.dirty && now - drive.sentAt < 100) return;  // unchanged: a keep-alive every 100 ms
    const b = new ArrayBuffer(64), d = new DataView(b);
    [83, 84, 86, 80].forEach((c, i) => d.setUint8(i, c));  // "STVP"
    d.setUint32(4, 0, true);
    const v = [drive.tip[0], drive.tip[1], drive.tip[2], 1, 0, 0, 0];
    v.forEach((x, i) => d.setFloat64(8 + 8 * i, x, true));
    ws.send(b);
    drive.dirty = false;
    drive.sentAt = now;
  }

  let ws = null;
  function connect() {
    ws = new WebSocket(`ws://${location.host}/ws?t=${encodeURIComponent(params.get('t') || '')}`);
    ws.binaryType = 'arraybuffer';
    ws.onopen = () => { errorEl.textContent = ''; };
    ws.onmessage = (ev) => {
      if (typeof ev.data === 'string') {
        const m = JSON.parse(ev.data);
        if (m.device === 'browser' && Array.isArray(m.home)) startDriving(m.home);
        return;
      }
      if (!(ev.data instanceof ArrayBuffer) || ev.data.byteLength < 8) return;
      const magic = String.fromCharCode(...new Uint8Array(ev.data, 0, 4));
      if (magic === 'STVM') onMesh(ev.data);
      else if (magic === 'STVF' && ev.data.byteLength >= 248) onFrame(ev.data);
    };
    ws.onclose = () => {
      errorEl.textContent = 'disconnected from the run (it ended, or the server stopped); retrying ...';
      setTimeout(connect, 1000);
    };
  }
  connect();

  function sendSnapshot() {
    const url = renderer.domElement.toDataURL('image/png');
    const bin = atob(url.slice(url.indexOf(',') + 1));
    const out = new Uint8Array(4 + bin.length);
    out.set([83, 84, 86, 83]);  // "STVS"
    for (let i = 0; i < bin.length; ++i) out[4 + i] = bin.charCodeAt(i);
    ws.send(out.buffer);
  }

  function tick(now) {
    requestAnimationFrame(tick);
    pollGamepad(now);
    synthetic();
    sendPose(now);
    if (last && fresh) apply(last);  // only what changed: a frame's overlays are rebuilt once
    fresh = false;
    controls.update();
    draw();
    ++drawn;
    ++fpsFrames;
    if (wantSnapshot && !snapshotSent && object && object.count >= 30 && now - meshAt > 300 &&
        ws && ws.readyState === 1) {
      sendSnapshot();  // right after render: the drawing buffer still holds this frame
      snapshotSent = true;
    }
    if (now - fpsSince >= 1000) {
      fps = (1000 * fpsFrames) / (now - fpsSince);
      fpsFrames = 0;
      fpsSince = now;
      if (ws && ws.readyState === 1)
        ws.send(JSON.stringify({ fps: fps, frames: drawn, seconds: (now - startedAt) / 1000, red: object ? object.count : 0 }));
    }
    window.stView = { frames: drawn, fps: fps, red: object ? object.count : 0, objectDraws: still.draws,
                      connected: !!(ws && ws.readyState === 1) };
  }
  requestAnimationFrame(tick);
})();
