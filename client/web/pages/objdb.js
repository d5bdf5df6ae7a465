// objdb web: what every page shares (API calls, errors, numbers, the 3D viewer).
"use strict";

const objdb = {
  // GET a JSON endpoint; throws Error(message) with the server's explanation on failure.
  async api(path) {
    const response = await fetch(path);
    const type = response.headers.get("content-type") || "";
    const body = type.includes("json") ? await response.json() : null;
    if (!response.ok) {
      throw new Error((body && body.error) || `${path}: HTTP ${response.status}`);
    }
    return body;
  },

  // Shows an error in the page's banner (and keeps it for tests: window.objdbErrors).
  fail(error) {
    const banner = document.getElementById("error");
    window.objdbErrors = (window.objdbErrors || []).concat([String(error.message || error)]);
    if (banner) {
      banner.textContent = String(error.message || error);
      banner.style.display = "block";
    }
  },

  param(name) { return new URLSearchParams(window.location.search).get(name); },
  num(x) { return Number(x || 0); },  // uint64 fields arrive as strings
  // "1 pose", "3 poses".
  counted(x, noun, plural) { const n = Number(x || 0); return `${n} ${n === 1 ? noun : (plural || noun + "s")}`; },
  fixed(x, digits) { return Number(x || 0).toFixed(digits); },
  esc(text) {
    return String(text).replace(/[&<>"']/g, c => ({"&": "&amp;", "<": "&lt;", ">": "&gt;",
                                                   '"': "&quot;", "'": "&#39;"}[c]));
  },
  when(seconds) { return seconds ? new Date(seconds * 1000).toISOString().replace(".000", "") : ""; },

  // A proto Pose {x, y, z, qx, qy, qz, qw} as a THREE.Matrix4.
  matrix(pose) {
    const q = new THREE.Quaternion(pose.qx, pose.qy, pose.qz, pose.qw).normalize();
    return new THREE.Matrix4().compose(new THREE.Vector3(pose.x, pose.y, pose.z), q,
                                       new THREE.Vector3(1, 1, 1));
  },

  // A three.js view in `element` (z up, as the datasets' worlds): orbit with the mouse.
  viewer(element) {
    const renderer = new THREE.WebGLRenderer({antialias: true, preserveDrawingBuffer: true});
    renderer.setPixelRatio(window.devicePixelRatio);
    renderer.setSize(element.clientWidth, element.clientHeight);
    renderer.setClearColor(0xffffff);
    element.appendChild(renderer.domElement);
    const scene = new THREE.Scene();
    scene.add(new THREE.HemisphereLight(0xffffff, 0x667788, 0.9));
    const light = new THREE.DirectionalLight(0xffffff, 0.5);
    light.position.set(1, -1, 2);
    scene.add(light);
    const camera = new THREE.PerspectiveCamera(50, element.clientWidth / element.clientHeight,
                                               0.01, 1000);
    camera.up.set(0, 0, 1);
    const controls = new THREE.OrbitControls(camera, renderer.domElement);
    const view = {
      scene, camera, renderer, controls,
      render() { renderer.render(scene, camera); },
      // Frames `object` (or everything) from the front left and above.
      fit(object) {
        const box = new THREE.Box3().setFromObject(object || scene);
        if (box.isEmpty()) return;
        const centre = box.getCenter(new THREE.Vector3());
        const radius = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 0.05);
        camera.position.copy(centre).add(new THREE.Vector3(-1.2, -1.6, 1.1)
                                         .normalize().multiplyScalar(radius * 1.9));
        camera.near = radius / 100;
        camera.far = radius * 100;
        camera.updateProjectionMatrix();
        controls.target.copy(centre);
        controls.update();
        view.render();
      },
    };
    controls.addEventListener("change", view.render);
    window.addEventListener("resize", () => {
      camera.aspect = element.clientWidth / element.clientHeight;
      camera.updateProjectionMatrix();
      renderer.setSize(element.clientWidth, element.clientHeight);
      view.render();
    });
    return view;
  },

  // A PLY from `url` as a THREE.BufferGeometry (errors carry the server's message).
  async ply(url) {
    const response = await fetch(url);
    if (!response.ok) {
      let message = `${url}: HTTP ${response.status}`;
      try { message = (await response.json()).error || message; } catch (e) { /* not JSON */ }
      throw new Error(message);
    }
    const geometry = new THREE.PLYLoader().parse(await response.arrayBuffer());
    if (!geometry.getAttribute("normal")) geometry.computeVertexNormals();
    return geometry;
  },

  // A mesh of `geometry`: its vertex colours when it has them, else `colour`.
  mesh(geometry, colour, opacity) {
    const coloured = !!geometry.getAttribute("color") && colour === undefined;
    const material = new THREE.MeshLambertMaterial({
      vertexColors: coloured ? THREE.VertexColors : THREE.NoColors,
      color: coloured ? 0xffffff : (colour === undefined ? 0xb0bec5 : colour),
      side: THREE.DoubleSide, transparent: opacity !== undefined, opacity: opacity || 1});
    return new THREE.Mesh(geometry, material);
  },
};

window.addEventListener("error", e => objdb.fail(e.error || e.message));
window.addEventListener("unhandledrejection", e => objdb.fail(e.reason));
