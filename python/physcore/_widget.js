// The physcore notebook widget's front end (anywidget ES module; python/physcore/notebook.py).
//
// The kernel runs the scene (physcore._live, the viewer's loop) and sends frames as images in
// binary buffers; this module draws them on a canvas and sends back what the user does. Flow
// control: the kernel sends a frame only against a credit; "ready" grants two, and each frame
// drawn gives one back ("ack", on the next animation frame, at most max_fps a second), so that
// frames never pile up beyond what the browser draws (at most the display's rate, and slower
// when the kernel or the link is slower). Pointer moves are coalesced to one message per animation frame.

function el(tag, cls, text) {
  const e = document.createElement(tag);
  if (cls) e.className = cls;
  if (text !== undefined) e.textContent = text;
  return e;
}

function fmt(v) {
  if (v === 0) return "0";
  const a = Math.abs(v);
  return a >= 1e4 || a < 1e-3 ? v.toExponential(3) : v.toPrecision(4);
}

function render({ model, el: root }) {
  const [w, h] = model.get("size");
  const box = el("div", "physcore-widget");
  const canvas = el("canvas", "pc-frame");
  canvas.width = w;
  canvas.height = h;
  canvas.style.touchAction = "none";
  const ctx = canvas.getContext("2d");
  const bar = el("div", "pc-bar");
  const play = el("button", "pc-play");
  const step = el("button", "pc-step", "step");
  const reset = el("button", "pc-reset", "reset");
  const clock = el("span", "pc-time", "t = 0 s");
  const status = el("span", "pc-status", "");
  step.title = "one tick (one GIF frame); pauses";
  reset.title = "back to the start (keeps the parameters)";
  bar.append(play, step, reset, clock, status);
  const sliders = el("div", "pc-sliders");
  box.append(canvas, bar, sliders);
  root.append(box);

  let frames = 0;
  let lastAck = 0;
  let closed = false;
  const labels = {};
  const inputs = {};
  box.dataset.frames = "0";

  const showPlaying = () => {
    const on = model.get("playing");
    play.textContent = on ? "pause" : "play";
    box.dataset.playing = on ? "1" : "0";
  };
  play.addEventListener("click", () => {
    model.set("playing", !model.get("playing"));
    model.save_changes();
  });
  step.addEventListener("click", () => model.send({ type: "step" }));
  reset.addEventListener("click", () => model.send({ type: "reset" }));
  model.on("change:playing", showPlaying);
  showPlaying();

  const buildSliders = () => {
    sliders.replaceChildren();
    for (const s of model.get("sliders")) {
      const row = el("label", "pc-slider");
      row.dataset.name = s.name;
      const input = el("input");
      input.type = "range";
      input.min = "0";
      input.max = String(s.positions);
      input.step = "1";
      input.value = String(s.position);
      input.name = s.name;
      const value = el("span", "pc-value", `${fmt(s.value)} ${s.unit}`);
      row.append(el("span", "pc-name", `${s.name} ${s.label}`), input, value);
      input.addEventListener("input", () => model.send({ type: "param", name: s.name, position: Number(input.value) }));
      labels[s.name] = [value, s.unit];
      inputs[s.name] = input;
      sliders.append(row);
    }
  };
  model.on("change:sliders", buildSliders);
  buildSliders();

  // The pointer, in the image's pixels (the canvas may be drawn scaled).
  const pixel = (e) => {
    const r = canvas.getBoundingClientRect();
    return { x: ((e.clientX - r.left) * canvas.width) / r.width, y: ((e.clientY - r.top) * canvas.height) / r.height };
  };
  let held = false;
  let pending = null;
  canvas.addEventListener("pointerdown", (e) => {
    if (e.button !== 0) return;
    // Where it was pressed, before anything moves: focusing, or the notebook making this cell
    // the active one, may scroll the page.
    const at = pixel(e);
    held = true;
    canvas.focus({ preventScroll: true });
    canvas.setPointerCapture(e.pointerId);
    model.send({ type: "down", ...at });
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!held) return;
    if (pending === null) {
      requestAnimationFrame(() => {
        if (pending !== null && !closed) model.send({ type: "move", ...pending });
        pending = null;
      });
    }
    pending = pixel(e);
  });
  const up = (e) => {
    if (!held) return;
    held = false;
    if (pending !== null) {
      model.send({ type: "move", ...pending });
      pending = null;
    }
    model.send({ type: "up", ...pixel(e) });
  };
  // The viewer's keys on the focused picture (physcore.viewer.KEYS, less quit and screenshot);
  // JupyterLab's own shortcuts stand aside there.
  canvas.tabIndex = 0;
  box.dataset.lmSuppressShortcuts = "true";
  const KEYS = [" ", ".", "ArrowRight", "r", "[", "]", "-", "=", "+", "_", "g", "G", "d", "D"];
  canvas.addEventListener("keydown", (e) => {
    if (e.ctrlKey || e.metaKey || e.altKey || !KEYS.includes(e.key)) return;
    e.preventDefault();
    e.stopPropagation();
    model.send({ type: "key", key: e.key });
  });
  canvas.addEventListener("pointerup", up);
  canvas.addEventListener("pointercancel", up);

  const onMessage = async (msg, buffers) => {
    if (!msg || msg.type !== "frame" || closed) return;
    try {
      const blob = new Blob([buffers[0]], { type: msg.mime });
      const image = await createImageBitmap(blob);
      ctx.drawImage(image, 0, 0);
      image.close();
    } finally {
      frames += 1;
      box.dataset.frames = String(frames);
      box.dataset.time = String(msg.time);
      box.dataset.seq = String(msg.seq);
      clock.textContent = `t = ${msg.time.toFixed(3)} s`;
      status.textContent = msg.status || "";
      // The kernel's answer to a press: the particle it holds ("" for none).
      const grabbed = Number.isInteger(msg.grabbed) ? String(msg.grabbed) : "";
      box.dataset.grabbed = grabbed;
      box.dataset.body = Number.isInteger(msg.body) ? String(msg.body) : "";
      canvas.classList.toggle("pc-holding", grabbed !== "" || box.dataset.body !== "");
      for (const [name, v] of Object.entries(msg.params || {})) {
        if (labels[name]) labels[name][0].textContent = `${fmt(v)} ${labels[name][1]}`;
      }
      // The credit goes back on the next animation frame, and no sooner than 1 / max_fps
      // after the last one.
      const wait = Math.max(0, lastAck + 1000 / model.get("max_fps") - performance.now());
      setTimeout(() => requestAnimationFrame(() => {
        if (closed) return;
        lastAck = performance.now();
        model.send({ type: "ack", seq: msg.seq });
      }), wait);
    }
  };
  model.on("msg:custom", onMessage);
  model.send({ type: "ready" });
  return () => {
    closed = true;
    model.off("msg:custom", onMessage);
    model.off("change:playing", showPlaying);
    model.off("change:sliders", buildSliders);
  };
}

export default { render };
