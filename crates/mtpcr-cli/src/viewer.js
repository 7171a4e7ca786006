// The interactive part of view.html (see viewer.rs). Plain ES5-style script: it runs after
// three.js and OrbitControls (both embedded as classic scripts) and reads its data from the
// JSON block #mtpcr-data. Renders on demand (after each change), not in a loop.
(function () {
  "use strict";
  var data = JSON.parse(document.getElementById("mtpcr-data").textContent);
  var canvas = document.getElementById("view");
  var STATES = ["before", "after"];
  var STATE_TEXT = {
    before: "Before registration: each scan in its own frame",
    after: "After registration: all scans in the common frame",
  };
  var DEFAULT_DIR = [0.3, 0.35, 1.0]; // from the front (+z), a little right and above

  function fail(message) {
    var el = document.getElementById("error");
    el.textContent = message;
    el.style.display = "block";
    document.getElementById("scale").style.display = "none";
  }

  function decode(b64) {
    var bin = atob(b64);
    var bytes = new Uint8Array(bin.length);
    for (var i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    // Little-endian f32, as written by viewer.rs (every WebGL platform is little-endian).
    return new Float32Array(bytes.buffer);
  }

  function fmt(x) {
    if (x === 0) return "0";
    var s = Number(x.toPrecision(3));
    return Math.abs(s) >= 1e-3 && Math.abs(s) < 1e6 ? String(s) : s.toExponential();
  }
  var unitText = data.units ? " " + data.units : "";
  var barUnitText = data.units ? " " + data.units : " units";

  if (typeof THREE === "undefined" || !THREE.OrbitControls) {
    fail("three.js did not load.");
    return;
  }
  var renderer;
  try {
    renderer = new THREE.WebGLRenderer({
      canvas: canvas,
      antialias: true,
      preserveDrawingBuffer: true,
    });
  } catch (e) {
    fail("WebGL is not available in this browser, so the 3-D view cannot be shown. (" + e.message + ")");
    return;
  }
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setClearColor(new THREE.Color(data.background), 1);

  var scene = new THREE.Scene();
  var camera = new THREE.PerspectiveCamera(40, 1, 1e-3, 1e3);
  var controls = new THREE.OrbitControls(camera, canvas);
  controls.screenSpacePanning = true;
  controls.enableKeys = false; // our own keys below; arrow keys stay with the page
  controls.zoomSpeed = 1.2;

  var pointSize = Number(document.getElementById("size").value);
  var materials = [];
  var objects = { before: [], after: [] };
  var bounds = {};
  var visible = [];
  var state = "after";

  STATES.forEach(function (s) {
    var lo = [Infinity, Infinity, Infinity];
    var hi = [-Infinity, -Infinity, -Infinity];
    var arrays = data[s].map(decode);
    arrays.forEach(function (a) {
      for (var i = 0; i < a.length; i += 3) {
        for (var k = 0; k < 3; k++) {
          var v = a[i + k];
          if (v < lo[k]) lo[k] = v;
          if (v > hi[k]) hi[k] = v;
        }
      }
    });
    var empty = !(lo[0] <= hi[0]);
    var center = empty ? [0, 0, 0] : [0, 1, 2].map(function (k) { return (lo[k] + hi[k]) / 2; });
    var radius = 0;
    arrays.forEach(function (a) {
      for (var i = 0; i < a.length; i += 3) {
        var dx = a[i] - center[0], dy = a[i + 1] - center[1], dz = a[i + 2] - center[2];
        var r2 = dx * dx + dy * dy + dz * dz;
        if (r2 > radius) radius = r2;
      }
    });
    radius = Math.sqrt(radius) || 1;
    bounds[s] = {
      center: new THREE.Vector3(center[0], center[1], center[2]),
      radius: radius,
      size: empty ? [0, 0, 0] : [0, 1, 2].map(function (k) { return hi[k] - lo[k]; }),
    };
    arrays.forEach(function (a, i) {
      if (!materials[i]) {
        var c = data.colors[i];
        materials[i] = new THREE.PointsMaterial({
          color: new THREE.Color(c[0] / 255, c[1] / 255, c[2] / 255),
          size: pointSize,
          sizeAttenuation: false,
        });
        visible[i] = true;
      }
      var g = new THREE.BufferGeometry();
      g.setAttribute("position", new THREE.BufferAttribute(a, 3));
      var p = new THREE.Points(g, materials[i]);
      p.frustumCulled = false;
      scene.add(p);
      objects[s].push(p);
    });
  });

  function render() {
    renderer.render(scene, camera);
    updateScaleBar();
  }

  function resize() {
    var w = window.innerWidth, h = window.innerHeight;
    renderer.setSize(w, h, false);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    render();
  }

  // Distance at which a sphere of this radius fills the view (the smaller of the two fovs).
  function fitDistance(radius) {
    var v = (camera.fov * Math.PI) / 180;
    var h = 2 * Math.atan(Math.tan(v / 2) * camera.aspect);
    return (radius / Math.sin(Math.min(v, h) / 2)) * 1.1;
  }

  function frame(b, direction) {
    var d = fitDistance(b.radius);
    controls.target.copy(b.center);
    camera.position.copy(b.center).addScaledVector(direction.clone().normalize(), d);
    camera.up.set(0, 1, 0);
    camera.near = b.radius / 1000;
    camera.far = d + b.radius * 100;
    camera.updateProjectionMatrix();
    controls.update();
  }

  function resetView() {
    frame(bounds[state], new THREE.Vector3(DEFAULT_DIR[0], DEFAULT_DIR[1], DEFAULT_DIR[2]));
    render();
  }

  function applyVisibility() {
    STATES.forEach(function (s) {
      objects[s].forEach(function (p, i) {
        p.visible = s === state && visible[i];
      });
    });
  }

  function setState(s) {
    state = s;
    applyVisibility();
    var other = s === "after" ? "before" : "after";
    document.getElementById("toggle").textContent = "Show " + other + " (B)";
    document.getElementById("state").textContent = STATE_TEXT[s];
    document.body.setAttribute("data-state", s);
    var z = bounds[s].size;
    document.getElementById("extent").textContent =
      "Extent: " + fmt(z[0]) + " \u00d7 " + fmt(z[1]) + " \u00d7 " + fmt(z[2]) + unitText;
    // Keep the user's view unless the new state falls outside it; then frame it from the
    // same direction.
    var b = bounds[s];
    var dist = camera.position.distanceTo(controls.target);
    var seen = dist * Math.sin((camera.fov * Math.PI) / 360);
    if (b.center.distanceTo(controls.target) > 0.5 * seen || b.radius > 1.5 * seen) {
      frame(b, camera.position.clone().sub(controls.target));
    }
    render();
  }

  function niceLength(x) {
    var p = Math.pow(10, Math.floor(Math.log10(x)));
    var m = x / p;
    return (m >= 5 ? 5 : m >= 2 ? 2 : 1) * p;
  }

  function updateScaleBar() {
    var h = canvas.clientHeight || window.innerHeight;
    var dist = camera.position.distanceTo(controls.target);
    var worldPerPx = (2 * dist * Math.tan((camera.fov * Math.PI) / 360)) / h;
    if (!(worldPerPx > 0) || !isFinite(worldPerPx)) return;
    var len = niceLength(120 * worldPerPx);
    document.getElementById("bar").style.width = Math.round(len / worldPerPx) + "px";
    document.getElementById("bar-label").textContent = fmt(len) + barUnitText;
  }

  function setSize(v) {
    pointSize = v;
    materials.forEach(function (m) {
      m.size = v;
    });
    document.getElementById("size-value").textContent = String(v);
    render();
  }

  function setScanVisible(i, on) {
    visible[i] = on;
    var box = document.querySelector('input[data-scan="' + i + '"]');
    if (box) box.checked = on;
    applyVisibility();
    render();
  }

  controls.addEventListener("change", render);
  window.addEventListener("resize", resize);
  document.getElementById("toggle").addEventListener("click", function () {
    setState(state === "after" ? "before" : "after");
  });
  document.getElementById("reset").addEventListener("click", resetView);
  document.getElementById("size").addEventListener("input", function (e) {
    setSize(Number(e.target.value));
  });
  Array.prototype.forEach.call(document.querySelectorAll("input[data-scan]"), function (box) {
    box.addEventListener("change", function () {
      setScanVisible(Number(box.getAttribute("data-scan")), box.checked);
    });
  });
  window.addEventListener("keydown", function (e) {
    if (e.ctrlKey || e.metaKey || e.altKey) return;
    var k = e.key;
    if (k === "b" || k === "B") {
      setState(state === "after" ? "before" : "after");
    } else if (k === "r" || k === "R") {
      resetView();
    } else if (k === "h" || k === "H") {
      document.body.classList.toggle("bare");
    } else if (k.length === 1 && k >= "0" && k <= "9") {
      var i = k === "0" ? 9 : Number(k) - 1;
      if (i < visible.length) setScanVisible(i, !visible[i]);
    } else {
      return;
    }
    e.preventDefault();
  });

  var w = window.innerWidth, h = window.innerHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  // view.html?state=before or view.html#before opens on the "before" state.
  var initial = new URLSearchParams(window.location.search).get("state") || window.location.hash.slice(1);
  state = initial === "before" ? "before" : "after";
  resetView();
  setState(state);
  document.body.setAttribute("data-ready", "1");
})();
