// persuasive drive: the study page. The server is the clock; this page only draws what it is
// sent and reports the person's controls. Protocol: persuasive/web/session.py.
(() => {
  "use strict";

  const $ = (id) => document.getElementById(id);
  const params = new URLSearchParams(location.search);
  const token = params.get("token");
  const COLOR = { hv: "#1f77b4", av: "#d62728" };
  const SECTIONS = ["welcome", "ready", "drive", "done", "finished", "lost"];
  // Render this far behind the newest state so that a late message still has a successor
  // to interpolate towards [ms].
  const RENDER_DELAY_MS = 60;

  let ws = null;
  let ended = false; // study finished: a closed socket is expected
  let questions = [];
  let trial = null; // {index, label, ...} of the current trial
  let scene = null; // the trial's geometry (persuasive/web/scene.py)
  let states = []; // [{j, t, av: [x, y, h, v], hv: [...], belief, at}]
  let view = null; // world-to-canvas transform
  let background = null; // the scene pre-drawn once per size
  let countdownEnd = 0;
  let driving = false;

  const input = { kbUp: false, kbDown: false, touchUp: false, touchDown: false, axis: null,
                  source: "none" };
  let lastInput = "";
  let seq = 0;

  function show(id) {
    for (const s of SECTIONS) $(s).hidden = s !== id;
  }

  // -- the connection ------------------------------------------------------------------------

  function connect() {
    const scheme = location.protocol === "https:" ? "wss://" : "ws://";
    const query = token ? "?token=" + encodeURIComponent(token) : "";
    ws = new WebSocket(scheme + location.host + "/ws" + query);
    ws.onopen = () => sendInput();
    ws.onmessage = (event) => {
      let msg;
      try { msg = JSON.parse(event.data); } catch (e) { return; }
      if (msg && typeof msg.type === "string" && handlers[msg.type]) handlers[msg.type](msg);
    };
    ws.onclose = () => {
      driving = false;
      if (!ended) show("lost");
    };
  }

  function send(obj) {
    if (!ws || ws.readyState !== WebSocket.OPEN) return false;
    ws.send(JSON.stringify(obj));
    return true;
  }

  const handlers = {
    welcome(msg) {
      $("title").textContent = msg.title;
      document.title = msg.title;
      $("consent-text").textContent = msg.consent;
      const given = params.get("participant");
      if (given) {
        $("participant").value = given;
        $("participant").readOnly = true;
      }
      show("welcome");
      updateBegin();
    },
    error(msg) {
      if (msg.field) { // a refused "begin"
        $("welcome-error").textContent = msg.message;
        $("begin").disabled = false;
        return;
      }
      ended = true;
      driving = false;
      $("lost").querySelector("p").textContent = msg.message;
      show("lost");
    },
    plan(msg) {
      questions = msg.questions || [];
      $("instructions").textContent = msg.instructions;
    },
    ready(msg) {
      trial = msg;
      $("ready-progress").textContent = "Trial " + msg.number + " of " + msg.of;
      $("ready-title").textContent = msg.label;
      $("start").disabled = false;
      show("ready");
      $("start").focus();
    },
    scene(msg) {
      scene = msg.scene;
      scene.dt = msg.dt_s;
      scene.nSteps = msg.n_steps;
      scene.countdown = msg.countdown_s;
      trial = Object.assign({}, trial || {}, { index: msg.trial, label: msg.label });
      states = [Object.assign({ at: performance.now() }, msg.state)];
      $("trial-label").textContent = msg.label;
      $("clock").textContent = "0.0 s / " + (msg.dt_s * msg.n_steps).toFixed(1) + " s";
      $("belief").hidden = true;
      countdownEnd = performance.now() + 1000 * msg.countdown_s;
      show("drive");
      resize();
      driving = true;
    },
    state(msg) {
      msg.at = performance.now();
      states.push(msg);
      if (states.length > 400) states.splice(0, states.length - 400);
      if (typeof msg.belief === "number") {
        $("belief").hidden = false;
        // the AV's probability that the person leads (goes first)
        $("belief-bar").style.width = (100 * msg.belief).toFixed(1) + "%";
        $("belief-value").textContent = (100 * msg.belief).toFixed(0) + "%";
      }
    },
    done(msg) {
      driving = false;
      $("done-title").textContent = (trial && trial.practice ? "Practice" : "Trial") +
        " complete";
      buildQuestions(msg.questions ? questions : []);
      $("next").textContent = msg.last ? "Finish" : "Next";
      $("next").dataset.trial = String(msg.trial);
      show("done");
    },
    finished() {
      ended = true;
      show("finished");
    },
  };

  // -- welcome and questionnaire -------------------------------------------------------------

  function updateBegin() {
    $("begin").disabled = !($("consent").checked && $("participant").value.trim());
  }

  function buildQuestions(items) {
    const form = $("questions");
    form.textContent = "";
    for (const q of items) {
      const set = document.createElement("fieldset");
      set.className = "question";
      const legend = document.createElement("legend");
      legend.textContent = q.text;
      set.appendChild(legend);
      const row = document.createElement("div");
      row.className = "likert";
      const low = document.createElement("span");
      low.className = "end";
      low.textContent = q.low || "";
      row.appendChild(low);
      for (let v = 1; v <= q.scale; v++) {
        const label = document.createElement("label");
        const radio = document.createElement("input");
        radio.type = "radio";
        radio.name = "q-" + q.id;
        radio.value = String(v);
        radio.dataset.testid = "q-" + q.id + "-" + v;
        radio.addEventListener("change", updateNext);
        label.appendChild(radio);
        label.appendChild(document.createTextNode(String(v)));
        row.appendChild(label);
      }
      const high = document.createElement("span");
      high.className = "end";
      high.textContent = q.high || "";
      row.appendChild(high);
      set.appendChild(row);
      form.appendChild(set);
    }
    form.dataset.ids = JSON.stringify(items.map((q) => q.id));
    updateNext();
  }

  function answers() {
    const out = {};
    for (const id of JSON.parse($("questions").dataset.ids || "[]")) {
      const checked = document.querySelector('input[name="q-' + id + '"]:checked');
      if (!checked) return null;
      out[id] = parseInt(checked.value, 10);
    }
    return out;
  }

  function updateNext() {
    $("next").disabled = answers() === null;
  }

  // -- controls: keyboard, on-screen pedals, gamepad -----------------------------------------

  function sendInput() {
    const msg = {
      type: "input",
      up: input.kbUp || input.touchUp,
      down: input.kbDown || input.touchDown,
      axis: input.axis,
      source: input.source,
    };
    const key = JSON.stringify(msg);
    if (key === lastInput) return;
    msg.seq = seq + 1;
    if (send(msg)) { // a change made before the socket opened is sent when it opens
      seq += 1;
      lastInput = key;
    }
  }

  function onKey(event, down) {
    const target = event.target;
    const typing = target && (target.tagName === "INPUT" && target.type === "text");
    if (event.key === "ArrowUp") input.kbUp = down;
    else if (event.key === "ArrowDown") input.kbDown = down;
    else return;
    input.source = "keyboard";
    if (!typing) event.preventDefault();
    sendInput();
  }

  function pedal(el, key) {
    const release = () => {
      if (input[key]) {
        input[key] = false;
        sendInput();
      }
    };
    el.addEventListener("pointerdown", (event) => {
      event.preventDefault();
      try { el.setPointerCapture(event.pointerId); } catch (e) { /* not capturable */ }
      input[key] = true;
      input.source = "touch";
      sendInput();
    });
    el.addEventListener("pointerup", release);
    el.addEventListener("pointercancel", release);
    el.addEventListener("lostpointercapture", release);
    el.addEventListener("contextmenu", (event) => event.preventDefault());
  }

  function pollGamepad() {
    const pads = navigator.getGamepads ? navigator.getGamepads() : [];
    let pad = null;
    for (const p of pads) if (p && p.connected) { pad = p; break; }
    if (!pad) {
      if (input.axis !== null) { input.axis = null; sendInput(); }
      return;
    }
    let v = 0;
    if (pad.mapping === "standard" && pad.buttons.length > 7) {
      v = pad.buttons[7].value - pad.buttons[6].value; // right trigger - left trigger
    }
    if (Math.abs(v) < 0.05 && pad.axes.length > 1) v = -pad.axes[1]; // left stick, up = +
    if (Math.abs(v) < 0.08) v = 0; // dead zone
    v = Math.max(-1, Math.min(1, Math.round(v * 50) / 50));
    if (v !== input.axis) {
      input.axis = v;
      if (v !== 0) input.source = "gamepad";
      sendInput();
    }
  }

  // -- drawing -------------------------------------------------------------------------------

  function resize() {
    const canvas = $("scene");
    const dpr = window.devicePixelRatio || 1;
    canvas.width = Math.max(1, Math.round(canvas.clientWidth * dpr));
    canvas.height = Math.max(1, Math.round(canvas.clientHeight * dpr));
    const sp = $("speedometer");
    sp.width = Math.round(sp.clientWidth * dpr) || 220;
    sp.height = Math.round(sp.clientHeight * dpr) || 180;
    if (!scene) return;
    const [x0, y0, x1, y1] = scene.view;
    const scale = Math.min(canvas.width / (x1 - x0), canvas.height / (y1 - y0));
    view = {
      scale,
      tx: canvas.width / 2 - scale * (x0 + x1) / 2,
      ty: canvas.height / 2 + scale * (y0 + y1) / 2,
      dpr,
    };
    background = drawBackground(canvas.width, canvas.height);
  }

  const X = (x) => view.tx + view.scale * x;
  const Y = (y) => view.ty - view.scale * y;

  function polyline(ctx, pts) {
    ctx.beginPath();
    ctx.moveTo(X(pts[0][0]), Y(pts[0][1]));
    for (let i = 1; i < pts.length; i++) ctx.lineTo(X(pts[i][0]), Y(pts[i][1]));
  }

  function drawBackground(w, h) {
    const off = document.createElement("canvas");
    off.width = w;
    off.height = h;
    const ctx = off.getContext("2d");
    ctx.fillStyle = "#dfe7d6";
    ctx.fillRect(0, 0, w, h);
    const s = view.scale;
    const lane = scene.lane_width_m;
    ctx.lineJoin = "round";
    ctx.lineCap = "butt";
    for (const who of ["av", "hv"]) { // kerbs first, so that roads cover them where they meet
      polyline(ctx, scene.vehicles[who].path);
      ctx.strokeStyle = "#8d969c";
      ctx.lineWidth = (lane + 0.4) * s;
      ctx.stroke();
    }
    for (const who of ["av", "hv"]) {
      polyline(ctx, scene.vehicles[who].path);
      ctx.strokeStyle = "#c4c9cc";
      ctx.lineWidth = lane * s;
      ctx.stroke();
    }
    for (const who of ["av", "hv"]) {
      for (const line of scene.vehicles[who].lines) {
        const half = lane / 2;
        ctx.beginPath();
        ctx.moveTo(X(line.x - half * line.nx), Y(line.y - half * line.ny));
        ctx.lineTo(X(line.x + half * line.nx), Y(line.y + half * line.ny));
        ctx.strokeStyle = "#262b30";
        ctx.lineWidth = Math.max(2, 0.3 * s);
        ctx.setLineDash(line.kind === "yield" ? [0.6 * s, 0.4 * s] : []);
        ctx.stroke();
        ctx.setLineDash([]);
      }
    }
    const [cx, cy] = scene.conflict;
    ctx.beginPath();
    ctx.arc(X(cx), Y(cy), scene.min_dist_m * s, 0, 2 * Math.PI);
    ctx.strokeStyle = "rgba(40, 45, 50, 0.75)";
    ctx.lineWidth = Math.max(1.5, 0.08 * s);
    ctx.setLineDash([0.25 * s, 0.5 * s]);
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.beginPath();
    const r = 0.5 * s;
    ctx.moveTo(X(cx) - r, Y(cy));
    ctx.lineTo(X(cx) + r, Y(cy));
    ctx.moveTo(X(cx), Y(cy) - r);
    ctx.lineTo(X(cx), Y(cy) + r);
    ctx.lineWidth = Math.max(1, 0.08 * s);
    ctx.stroke();
    return off;
  }

  function drawVehicle(ctx, who, pose) {
    const v = scene.vehicles[who];
    const [x, y, h] = pose;
    const s = view.scale;
    const L = v.length_m * s;
    const W = v.width_m * s;
    ctx.save();
    ctx.translate(X(x), Y(y));
    ctx.rotate(-h); // world angles are counter-clockwise, canvas y points down
    ctx.fillStyle = COLOR[who];
    ctx.strokeStyle = "rgba(0, 0, 0, 0.55)";
    ctx.lineWidth = Math.max(1, 0.06 * s);
    ctx.beginPath();
    ctx.rect(-L / 2, -W / 2, L, W);
    ctx.fill();
    ctx.stroke();
    ctx.fillStyle = "rgba(255, 255, 255, 0.7)"; // windscreen: shows which way it faces
    ctx.fillRect(L * 0.12, -W * 0.38, L * 0.14, W * 0.76);
    ctx.restore();
    if (who === "hv") {
      ctx.font = "600 " + Math.round(13 * view.dpr) + "px system-ui, sans-serif";
      ctx.textAlign = "center";
      ctx.fillStyle = "#0d3c61";
      ctx.fillText("YOU", X(x), Y(y) - (Math.max(L, W) / 2 + 6 * view.dpr));
    }
  }

  function lerpAngle(a, b, u) {
    let d = b - a;
    while (d > Math.PI) d -= 2 * Math.PI;
    while (d < -Math.PI) d += 2 * Math.PI;
    return a + d * u;
  }

  // The poses to show now: states are placed on a local timeline (the earliest arrival of the
  // last few states relative to their step times), played RENDER_DELAY_MS behind it, and
  // interpolated between the two states around that time.
  function currentPoses(now) {
    if (states.length < 2) return { state: states[0], speed: states[0].hv[3] };
    let offset = Infinity;
    for (let i = Math.max(1, states.length - 10); i < states.length; i++) {
      offset = Math.min(offset, states[i].at - 1000 * states[i].t);
    }
    const t = (now - offset - RENDER_DELAY_MS) / 1000;
    let a = states[0];
    let b = states[states.length - 1];
    if (t >= b.t) return { state: b, speed: b.hv[3] };
    for (let i = states.length - 1; i > 0; i--) {
      if (states[i - 1].t <= t) { a = states[i - 1]; b = states[i]; break; }
    }
    if (t <= a.t) return { state: a, speed: a.hv[3] };
    const u = (t - a.t) / (b.t - a.t);
    const mix = (p, q) => [p[0] + (q[0] - p[0]) * u, p[1] + (q[1] - p[1]) * u,
      lerpAngle(p[2], q[2], u), p[3] + (q[3] - p[3]) * u];
    return { state: { t: a.t + (b.t - a.t) * u, av: mix(a.av, b.av), hv: mix(a.hv, b.hv) },
             speed: a.hv[3] + (b.hv[3] - a.hv[3]) * u };
  }

  function drawSpeedometer(speed) {
    const c = $("speedometer");
    const ctx = c.getContext("2d");
    const k = c.width / 220;
    ctx.setTransform(k, 0, 0, k, 0, 0);
    ctx.clearRect(0, 0, 220, 180);
    const vmax = Math.max(10, Math.ceil(scene.vehicles.hv.v_max_mps * 3.6 / 10) * 10);
    const kmh = Math.max(0, speed * 3.6);
    const cx = 110, cy = 108, r = 78;
    const a0 = 0.75 * Math.PI, a1 = 2.25 * Math.PI;
    const angle = (value) => a0 + (a1 - a0) * Math.min(value, vmax) / vmax;
    ctx.lineWidth = 8;
    ctx.strokeStyle = "#e1e5e8";
    ctx.beginPath();
    ctx.arc(cx, cy, r, a0, a1);
    ctx.stroke();
    ctx.strokeStyle = COLOR.hv;
    ctx.beginPath();
    ctx.arc(cx, cy, r, a0, angle(kmh));
    ctx.stroke();
    ctx.fillStyle = "#39424a";
    ctx.strokeStyle = "#39424a";
    ctx.lineWidth = 2;
    ctx.font = "12px system-ui, sans-serif";
    ctx.textAlign = "center";
    ctx.textBaseline = "middle";
    for (let v = 0; v <= vmax; v += 5) {
      const a = angle(v);
      const major = v % 10 === 0;
      const r0 = r - (major ? 16 : 11);
      ctx.beginPath();
      ctx.moveTo(cx + r0 * Math.cos(a), cy + r0 * Math.sin(a));
      ctx.lineTo(cx + (r - 6) * Math.cos(a), cy + (r - 6) * Math.sin(a));
      ctx.stroke();
      if (major) ctx.fillText(String(v), cx + (r - 28) * Math.cos(a), cy + (r - 28) * Math.sin(a));
    }
    const a = angle(kmh);
    ctx.strokeStyle = "#c0392b";
    ctx.lineWidth = 3;
    ctx.beginPath();
    ctx.moveTo(cx, cy);
    ctx.lineTo(cx + (r - 14) * Math.cos(a), cy + (r - 14) * Math.sin(a));
    ctx.stroke();
    ctx.beginPath();
    ctx.arc(cx, cy, 5, 0, 2 * Math.PI);
    ctx.fillStyle = "#39424a";
    ctx.fill();
    ctx.font = "600 22px system-ui, sans-serif";
    ctx.fillText(kmh.toFixed(0), cx, cy + 40);
    ctx.font = "12px system-ui, sans-serif";
    ctx.fillText("km/h", cx, cy + 60);
  }

  function frame(now) {
    requestAnimationFrame(frame);
    pollGamepad();
    $("go").classList.toggle("active", input.kbUp || input.touchUp || input.axis > 0);
    $("brake").classList.toggle("active", input.kbDown || input.touchDown || input.axis < 0);
    if (!scene || !view || $("drive").hidden) return;
    const canvas = $("scene");
    const ctx = canvas.getContext("2d");
    const { state, speed } = currentPoses(now);
    ctx.drawImage(background, 0, 0);
    drawVehicle(ctx, "av", state.av);
    drawVehicle(ctx, "hv", state.hv);
    drawSpeedometer(speed);
    const total = scene.dt * scene.nSteps;
    $("clock").textContent = state.t.toFixed(1) + " s / " + total.toFixed(1) + " s";
    const left = (countdownEnd - now) / 1000;
    const cd = $("countdown");
    if (driving && left > 0) {
      cd.hidden = false;
      cd.textContent = String(Math.ceil(left));
    } else if (driving && left > -0.6 && scene.countdown > 0) {
      cd.hidden = false;
      cd.textContent = "Go";
    } else {
      cd.hidden = true;
    }
  }

  // -- wiring --------------------------------------------------------------------------------

  function init() {
    $("participant").addEventListener("input", updateBegin);
    $("consent").addEventListener("change", updateBegin);
    $("begin").addEventListener("click", () => {
      $("begin").disabled = true;
      $("welcome-error").textContent = "";
      send({ type: "begin", participant: $("participant").value.trim(),
             consent: $("consent").checked });
    });
    $("start").addEventListener("click", () => {
      $("start").disabled = true;
      send({ type: "start" });
    });
    $("next").addEventListener("click", () => {
      const given = answers();
      if (given === null) return;
      $("next").disabled = true;
      send({ type: "answers", trial: parseInt($("next").dataset.trial, 10), answers: given });
    });
    window.addEventListener("keydown", (e) => { if (!e.repeat) onKey(e, true); else if (
      e.key === "ArrowUp" || e.key === "ArrowDown") e.preventDefault(); });
    window.addEventListener("keyup", (e) => onKey(e, false));
    window.addEventListener("blur", () => { // a released key is never seen by a hidden page
      input.kbUp = input.kbDown = input.touchUp = input.touchDown = false;
      sendInput();
    });
    window.addEventListener("resize", resize);
    pedal($("go"), "touchUp");
    pedal($("brake"), "touchDown");
    connect();
    requestAnimationFrame(frame);
  }

  init();
})();
