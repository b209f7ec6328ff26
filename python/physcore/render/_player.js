/* physcore's HTML player (physcore.render.html): plays the binary glTF embedded in this page with
   three.js r111 (global THREE, inlined above): an orbit camera (drag to turn, wheel to zoom, right
   drag to pan), play/pause (or the space bar) and a time slider. window.physcore is its state, for
   scripts and tests: ready, error, playing, time (s of playback), duration, frame, frames,
   background (sRGB; a backdrop's mean), and play(), pause(), setTime(t). MIT licence, as physcore. */
(function () {
  "use strict";
  // shown / drawn: a count of show() calls and the count the last render drew (equal once a
  // time set is on the canvas: what a test waits for before it reads the pixels).
  var state = window.physcore = { ready: false, error: null, playing: true, time: 0, duration: 0, frame: 0, frames: 1, shown: 0, drawn: -1 };
  function fail(e) {
    state.error = String(e && e.message || e);
    console.error("physcore player: " + state.error);
    var msg = document.getElementById("physcore-message");
    if (msg) { msg.textContent = "Cannot show this recording: " + state.error; msg.style.display = "block"; }
  }
  // r111's GLTFLoader calls updateMorphTargets on every primitive, which r111's lines lack
  // (springs between moving points): they take the meshes' (it reads only the geometry).
  if (THREE.Line && !THREE.Line.prototype.updateMorphTargets) THREE.Line.prototype.updateMorphTargets = THREE.Mesh.prototype.updateMorphTargets;
  var view = document.getElementById("physcore-view");
  var button = document.getElementById("physcore-play");
  var slider = document.getElementById("physcore-time");
  var clockText = document.getElementById("physcore-clock");
  var renderer;
  try {
    renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  } catch (e) {
    fail("WebGL is not available in this browser (" + (e && e.message || e) + ")");
    return;
  }
  renderer.gammaOutput = true;  // r111: sRGB output (glTF colours are linear; r112 renamed this outputEncoding)
  renderer.gammaFactor = 2.2;
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  view.appendChild(renderer.domElement);
  var scene = new THREE.Scene();
  var camera = new THREE.PerspectiveCamera(35, 1, 0.01, 1000);
  scene.add(camera);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x707070, 0.75));
  var sun = new THREE.DirectionalLight(0xffffff, 0.85);
  sun.position.set(-0.35, 0.45, 0.82);  // from the viewer's upper left, as the GIFs are lit
  camera.add(sun);
  var controls = new THREE.OrbitControls(camera, renderer.domElement);
  controls.enableDamping = false;
  var mixer = null, info = {}, times = [0], morphing = [];

  function resize() {
    var w = view.clientWidth || window.innerWidth, h = view.clientHeight || Math.max(1, window.innerHeight - 40);
    renderer.setSize(w, h);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
  }
  window.addEventListener("resize", resize);
  resize();

  function discTexture() {  // round points, shaded as balls lit from the upper left
    var c = document.createElement("canvas");
    c.width = c.height = 64;
    var g = c.getContext("2d");
    var grad = g.createRadialGradient(24, 22, 2, 32, 32, 32);
    grad.addColorStop(0, "rgb(255,255,255)");
    grad.addColorStop(0.75, "rgb(200,200,200)");
    grad.addColorStop(1, "rgb(150,150,150)");
    g.fillStyle = grad;
    g.beginPath(); g.arc(32, 32, 31, 0, 2 * Math.PI); g.fill();
    var tex = new THREE.CanvasTexture(c);
    tex.encoding = THREE.sRGBEncoding;
    return tex;
  }

  function gradientTexture(top, bottom) {  // the GIF's backdrop: a vertical gradient, sRGB 0-255
    var c = document.createElement("canvas");
    c.width = 2; c.height = 256;
    var g = c.getContext("2d"), grad = g.createLinearGradient(0, 0, 0, 256);
    grad.addColorStop(0, "rgb(" + top.join(",") + ")");
    grad.addColorStop(1, "rgb(" + bottom.join(",") + ")");
    g.fillStyle = grad;
    g.fillRect(0, 0, 2, 256);
    var tex = new THREE.CanvasTexture(c);
    tex.encoding = THREE.sRGBEncoding;
    return tex;
  }

  function sceneTime(t) {  // the scene's own time (s) at playback time t, between recorded frames
    var f = t * (info.fps || 30), k = Math.min(Math.floor(f), times.length - 1);
    if (k >= times.length - 1) return times[times.length - 1];
    return times[k] + (f - k) * (times[k + 1] - times[k]);
  }

  function show(t) {
    state.shown += 1;
    state.time = Math.max(0, Math.min(t, state.duration));
    // The last frame is at `duration`: a looping action wraps it to the first, so stop just short.
    if (mixer) mixer.setTime(Math.min(state.time, state.duration * (1 - 1e-7)));
    // Points and lines move by the same morph targets, but r111's GLTFLoader binds a weights
    // track to meshes only: their weights are set here, as the track would (LINEAR, frame k
    // showing target k - 1 alone).
    var f = state.time * (info.fps || 30), k = Math.min(Math.floor(f), state.frames - 1), a = f - k;
    for (var j = 0; j < morphing.length; j++) {
      var w = morphing[j].morphTargetInfluences;
      for (var m = 0; m < w.length; m++) w[m] = 0;
      if (k >= 1) w[k - 1] = k + 1 < state.frames ? 1 - a : 1;
      if (k + 1 < state.frames && a > 0) w[k] = a;
    }
    state.frame = Math.min(state.frames - 1, Math.round(state.time * (info.fps || 30)));
    slider.value = String(state.duration > 0 ? state.time / state.duration : 0);
    var st = sceneTime(state.time);
    clockText.textContent = "t = " + (Math.abs(st) < 0.01 && st !== 0 ? st.toExponential(2) : st.toFixed(3)) + " s  ·  frame " + state.frame;
  }
  state.setTime = function (t) { show(Number(t)); };
  state.play = function () { state.playing = true; button.textContent = "Pause"; };
  state.pause = function () { state.playing = false; button.textContent = "Play"; };
  button.addEventListener("click", function () { if (state.playing) state.pause(); else { if (state.time >= state.duration) show(0); state.play(); } });
  slider.addEventListener("input", function () { state.pause(); show(Number(slider.value) * state.duration); });
  window.addEventListener("keydown", function (e) { if (e.code === "Space" && e.target === document.body) { e.preventDefault(); button.click(); } });

  function frameView(bounds, dir) {
    // The camera along `dir` from the box's centre, as near as shows the whole box: its eight
    // corners on the view's right and up axes fit the field of view (in both directions).
    var lo = new THREE.Vector3().fromArray(bounds[0]), hi = new THREE.Vector3().fromArray(bounds[1]);
    var centre = lo.clone().add(hi).multiplyScalar(0.5);
    var d = new THREE.Vector3().fromArray(dir).normalize();
    var up = Math.abs(d.y) > 0.999 ? new THREE.Vector3(0, 0, -1) : new THREE.Vector3(0, 1, 0);
    var right = new THREE.Vector3().crossVectors(up, d).normalize();
    var upv = new THREE.Vector3().crossVectors(d, right);
    var tan = Math.tan(camera.fov * Math.PI / 360), dist = 1e-6, reach = 0;
    for (var i = 0; i < 8; i++) {
      var c = new THREE.Vector3(i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z).sub(centre);
      var toward = c.dot(d);  // the corner's depth toward the camera
      var need = Math.max(Math.abs(c.dot(upv)) / tan, Math.abs(c.dot(right)) / (tan * camera.aspect));
      dist = Math.max(dist, 1.08 * need + toward);
      reach = Math.max(reach, c.length());
    }
    camera.up.copy(up);
    camera.position.copy(centre).addScaledVector(d, dist);
    camera.near = Math.max(dist - 2 * reach, dist / 1000, 1e-6); camera.far = dist + 20 * reach + 1e-3;
    camera.updateProjectionMatrix();
    controls.target.copy(centre);
    controls.update();
  }

  function loaded(gltf) {
    info = (gltf.scene.userData && gltf.scene.userData.physcore) || {};
    times = info.times || [0];
    state.frames = info.frames || 1;
    state.duration = (state.frames - 1) / (info.fps || 30);
    var bg = state.background = info.background || [255, 255, 255];  // sRGB, 0-255
    renderer.setClearColor(new THREE.Color(bg[0] / 255, bg[1] / 255, bg[2] / 255).convertSRGBToLinear(), 1);
    if (info.backdrop) scene.background = gradientTexture(info.backdrop[0], info.backdrop[1]);
    var disc = discTexture();
    var pointScale = 1 / Math.tan(camera.fov * Math.PI / 360);
    gltf.scene.traverse(function (o) {
      if (o.isPoints) {
        var size = (o.userData.physcore && o.userData.physcore.point_size) || info.point_size || 0.02;
        o.material.size = size * pointScale;  // r111: gl_PointSize = size · (height / 2) / depth
        o.material.sizeAttenuation = true;
        o.material.map = disc;
        o.material.alphaTest = 0.5;
        o.material.needsUpdate = true;
      }
      if ((o.isPoints || o.isLine) && o.morphTargetInfluences && o.morphTargetInfluences.length) morphing.push(o);
      o.frustumCulled = false;  // morph targets move vertices beyond the base's bounding sphere
    });
    scene.add(gltf.scene);
    if (gltf.animations.length) {
      mixer = new THREE.AnimationMixer(gltf.scene);
      gltf.animations.forEach(function (clip) { mixer.clipAction(clip).play(); });
    }
    frameView(info.bounds || [[-1, -1, -1], [1, 1, 1]], info.view || [0, 0, 1]);
    show(0);
    state.ready = true;
  }

  try {
    var text = document.getElementById("physcore-glb").textContent.replace(/\s+/g, "");
    var raw = atob(text), bytes = new Uint8Array(raw.length);
    for (var i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
    new THREE.GLTFLoader().parse(bytes.buffer, "", loaded, fail);
  } catch (e) {
    fail(e);
  }

  var last = null;
  function tick(now) {
    if (last !== null && state.ready && state.playing && state.duration > 0) {
      var t = state.time + (now - last) / 1000;
      show(t > state.duration ? 0 : t);  // loops
    }
    last = now;
    controls.update();
    var shown = state.shown;
    renderer.render(scene, camera);
    state.drawn = shown;
    requestAnimationFrame(tick);
  }
  requestAnimationFrame(tick);
  state.renderer = renderer; state.camera = camera; state.controls = controls;
})();
