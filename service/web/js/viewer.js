// The 3D view: geoms from GET /v1/scene, posed by the streamed body poses.
//
// Every geom is one InstancedMesh with one instance per shown world, so the fleet view costs one
// draw per geom however many worlds it shows, and the world view is the same code with one.

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/OrbitControls.js';

THREE.Object3D.DEFAULT_UP.set(0, 0, 1); // MuJoCo is z-up

const _m = new THREE.Matrix4();
const _body = new THREE.Matrix4();
const _q = new THREE.Quaternion();
const _p = new THREE.Vector3();
const _one = new THREE.Vector3(1, 1, 1);

// Above this many worlds round shapes get fewer segments: a fleet of 64 has ~400k triangles at
// full detail, too many for software WebGL (measured 2.9 frames/s), and each arm is small there.
const LOW_DETAIL_WORLDS = 16;

function geometryOf(g, low = false) {
  const [a, b, c] = g.size;
  const radial = low ? 8 : 20, caps = low ? 2 : 6, rings = low ? 6 : 14;
  switch (g.type) {
    case 'box':
      return new THREE.BoxGeometry(2 * a, 2 * b, 2 * c);
    case 'sphere':
      return new THREE.SphereGeometry(a, radial, rings);
    case 'ellipsoid':
      return new THREE.SphereGeometry(1, radial, rings).scale(a, b, c);
    case 'capsule': // three.js builds along y; MuJoCo's axis is z
      return new THREE.CapsuleGeometry(a, 2 * b, caps, radial).rotateX(Math.PI / 2);
    case 'cylinder':
      return new THREE.CylinderGeometry(a, a, 2 * b, radial).rotateX(Math.PI / 2);
    case 'plane':
      return new THREE.PlaneGeometry(2 * (a || 1), 2 * (b || 1));
    case 'mesh': {
      const geo = new THREE.BufferGeometry();
      geo.setAttribute('position', new THREE.Float32BufferAttribute(g.mesh.vertices, 3));
      geo.setIndex(g.mesh.faces);
      geo.computeVertexNormals();
      return geo;
    }
    default:
      return null;
  }
}

/** WebGL drawn by the CPU (SwiftShader, llvmpipe): every frame drawn costs CPU time. */
function isSoftware(gl) {
  const ext = gl.getExtension('WEBGL_debug_renderer_info');
  const name = ext ? gl.getParameter(ext.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
  return /swiftshader|llvmpipe|softpipe|software/i.test(String(name));
}

export class Viewer {
  constructor(canvas, labels, onPick) {
    this.canvas = canvas;
    this.labels = labels;
    this.onPick = onPick;
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: false });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
    this.software = isSoftware(this.renderer.getContext());
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x30343c);
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.05, 500);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.addEventListener('change', () => (this.dirty = true));
    this.scene.add(new THREE.HemisphereLight(0xdde6f0, 0x40383a, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(2, -3, 5);
    this.scene.add(sun);
    this.meshes = [];
    this.ground = null;
    this.worlds = [];
    this.labelEls = [];
    this.spacing = 2.5;
    this.center = [0, 0];
    this.cols = 1;
    this.focus = null;
    this.dirty = true;
    this.renders = 0;
    new ResizeObserver(() => this.resize()).observe(canvas);
    this._pickHandlers();
  }

  /** Build the meshes of a scene description (GET /v1/scene). */
  setScene(desc) {
    for (const entry of this.meshes) {
      if (entry.mesh) this.scene.remove(entry.mesh);
      entry.geometry.dispose();
      entry.material.dispose();
    }
    this.meshes = [];
    this.nbody = desc.nbody;
    this.planes = [];
    for (const g of desc.geoms) {
      if (g.type === 'plane' && g.body === 0) {
        this.planes.push(g); // the floor: drawn once under the whole layout (see setWorlds)
        continue;
      }
      const geo = geometryOf(g);
      if (!geo) continue;
      const [r, gr, b, a] = g.rgba;
      const material = new THREE.MeshLambertMaterial({
        color: new THREE.Color().setRGB(r, gr, b, THREE.SRGBColorSpace),
        transparent: a < 1,
        opacity: a,
      });
      const local = new THREE.Matrix4().compose(
        new THREE.Vector3(...g.pos),
        new THREE.Quaternion(g.quat[1], g.quat[2], g.quat[3], g.quat[0]),
        _one,
      );
      this.meshes.push({ geom: g, local, material, geometry: geo, low: false, mesh: null });
    }
    this.worlds = [];
    this.dirty = true;
  }

  /** Show these world ids (one, or a fleet laid out in a grid). */
  setWorlds(ids, homePoses) {
    this.worlds = ids;
    const n = ids.length;
    this.cols = Math.ceil(Math.sqrt(n));
    this.spacing = this._spacing(homePoses);
    const low = n > LOW_DETAIL_WORLDS;
    for (const entry of this.meshes) {
      if (entry.mesh) {
        this.scene.remove(entry.mesh);
        entry.mesh.dispose();
      }
      if (entry.low !== low) {
        entry.geometry.dispose();
        entry.geometry = geometryOf(entry.geom, low);
        entry.low = low;
      }
      const mesh = new THREE.InstancedMesh(entry.geometry, entry.material, n);
      mesh.instanceMatrix.setUsage(THREE.DynamicDrawUsage);
      mesh.frustumCulled = false; // instances spread over the grid; bounds change every frame
      entry.mesh = mesh;
      this.scene.add(mesh);
    }
    this._buildGround(n);
    this._buildLabels(n > 1 ? ids : []);
    this.frame();
    this.dirty = true;
  }

  /** Where world slot i sits (fleet grid; slot 0 at the origin). */
  offset(i) {
    const s = this.spacing;
    return [(i % this.cols) * s, -Math.floor(i / this.cols) * s];
  }

  /** Pose every instance: poses is (n, nbody, 7) flat, x y z qw qx qy qz per body. */
  setPoses(poses) {
    const nb = this.nbody;
    for (const { geom, local, mesh } of this.meshes) {
      const arr = mesh.instanceMatrix.array;
      for (let i = 0; i < this.worlds.length; i++) {
        const k = (i * nb + geom.body) * 7;
        const [ox, oy] = this.offset(i);
        _p.set(poses[k] + ox, poses[k + 1] + oy, poses[k + 2]);
        _q.set(poses[k + 4], poses[k + 5], poses[k + 6], poses[k + 3]);
        _body.compose(_p, _q, _one);
        _m.multiplyMatrices(_body, local);
        _m.toArray(arr, i * 16);
      }
      mesh.instanceMatrix.needsUpdate = true;
    }
    this.dirty = true;
  }

  setFaults(faults) {
    faults.forEach((f, i) => {
      const el = this.labelEls[i];
      if (!el || el.dataset.faults === String(f)) return; // touch the DOM only on a change
      el.classList.toggle('faulted', f > 0);
      el.dataset.faults = String(f);
    });
  }

  setFocus(world) {
    this.focus = world;
    for (const el of this.labelEls) el.classList.toggle('focus', Number(el.dataset.world) === world);
  }

  /** Point the camera at what is shown. */
  frame() {
    const n = this.worlds.length;
    const rows = Math.ceil(n / this.cols);
    const cx = ((this.cols - 1) * this.spacing) / 2 + this.center[0];
    const cy = (-(rows - 1) * this.spacing) / 2 + this.center[1];
    const r = n > 1 ? Math.max(this.cols, rows) * this.spacing * 0.8 : 2.3;
    this.controls.target.set(cx, cy, n > 1 ? 0.2 : 0.6);
    this.camera.position.set(cx + 0.75 * r, cy - 1.0 * r, 0.4 + 0.8 * r);
    this.camera.far = 10 * r + 50;
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.dirty = true;
  }

  resize() {
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    if (!w || !h) return;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.dirty = true;
  }

  /** Draw if anything changed; returns whether it drew. */
  render() {
    if (!this.dirty || !this.worlds.length) return false;
    this.dirty = false;
    this.renderer.render(this.scene, this.camera);
    this.drawCalls = this.renderer.info.render.calls; // per frame: one per geom, any world count
    this._placeLabels();
    this.renders++;
    return true;
  }

  // -- internals ------------------------------------------------------------------------------

  _spacing(home) {
    // One world's footprint from its bodies at the first frame: centre, and a cell wide enough
    // for the bodies' spread plus a margin (the arm's reach beyond its links, the table).
    let lo = [0, 0], hi = [0, 0];
    if (home) {
      for (let k = 7; k < this.nbody * 7; k += 7) {
        lo = [Math.min(lo[0], home[k]), Math.min(lo[1], home[k + 1])];
        hi = [Math.max(hi[0], home[k]), Math.max(hi[1], home[k + 1])];
      }
    }
    this.center = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2];
    const r = Math.hypot(hi[0] - lo[0], hi[1] - lo[1]) / 2;
    return Math.ceil((2 * r + 1.6) * 2) / 2;
  }

  _buildGround(n) {
    if (this.ground) {
      this.scene.remove(this.ground);
      this.ground.traverse((o) => o.geometry?.dispose());
    }
    this.ground = new THREE.Group();
    if (this.planes.length) {
      const rows = Math.ceil(n / this.cols);
      const size = Math.max(this.cols, rows) * this.spacing + 2;
      const cx = ((this.cols - 1) * this.spacing) / 2 + this.center[0];
      const cy = (-(rows - 1) * this.spacing) / 2 + this.center[1];
      const floor = new THREE.Mesh(
        new THREE.PlaneGeometry(size, size),
        new THREE.MeshLambertMaterial({ color: 0x5a5f66 }),
      );
      floor.position.set(cx, cy, -0.001);
      const grid = new THREE.GridHelper(size, Math.round(size / 0.25), 0x8a9099, 0x6e737b);
      grid.rotation.x = Math.PI / 2;
      grid.position.set(cx, cy, 0);
      this.ground.add(floor, grid);
    }
    this.scene.add(this.ground);
  }

  _buildLabels(ids) {
    this.labels.replaceChildren();
    this.labelEls = ids.map((w) => {
      const el = document.createElement('button');
      el.className = 'wlabel';
      el.textContent = String(w);
      el.dataset.world = String(w);
      el.title = `world ${w}: click to drive it`;
      el.addEventListener('click', () => this.onPick(w));
      this.labels.append(el);
      return el;
    });
    this.setFocus(this.focus);
  }

  _placeLabels() {
    if (!this.labelEls.length) return;
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    const v = new THREE.Vector3();
    this.labelEls.forEach((el, i) => {
      const [ox, oy] = this.offset(i);
      v.set(ox + this.center[0], oy + this.center[1], 1.7).project(this.camera);
      const hidden = v.z > 1 || Math.abs(v.x) > 1.1 || Math.abs(v.y) > 1.1;
      el.style.display = hidden ? 'none' : '';
      el.style.left = `${((v.x + 1) / 2) * w}px`;
      el.style.top = `${((1 - v.y) / 2) * h}px`;
    });
  }

  _pickHandlers() {
    // A click (not an orbit drag) on the ground picks the world whose cell it falls in.
    let down = null;
    this.canvas.addEventListener('pointerdown', (e) => (down = [e.clientX, e.clientY]));
    this.canvas.addEventListener('pointerup', (e) => {
      if (!down || Math.hypot(e.clientX - down[0], e.clientY - down[1]) > 4) return;
      const w = this.pick(e.clientX, e.clientY);
      if (w !== null) this.onPick(w);
    });
  }

  /** World id under a screen point, or null (fleet view only). */
  pick(clientX, clientY) {
    if (this.worlds.length < 2) return null;
    const rect = this.canvas.getBoundingClientRect();
    const ndc = new THREE.Vector2(
      ((clientX - rect.left) / rect.width) * 2 - 1,
      -((clientY - rect.top) / rect.height) * 2 + 1,
    );
    const ray = new THREE.Raycaster();
    ray.setFromCamera(ndc, this.camera);
    const hit = ray.ray.intersectPlane(new THREE.Plane(new THREE.Vector3(0, 0, 1), 0), new THREE.Vector3());
    if (!hit) return null;
    const col = Math.round((hit.x - this.center[0]) / this.spacing);
    const row = Math.round(-(hit.y - this.center[1]) / this.spacing);
    if (col < 0 || col >= this.cols || row < 0) return null;
    const i = row * this.cols + col;
    return i < this.worlds.length ? this.worlds[i] : null;
  }
}
