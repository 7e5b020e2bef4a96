// The player of `cloth-usd preview`: plays the .glb embedded in the page (garment morph
// targets, skinned body) with a timeline. Bundled with three.js into
// cloth_usd/export/assets/preview.bundle.js by scripts/build_preview_bundle.sh.
import {
  AnimationMixer, Box3, Color, DirectionalLight, GridHelper, HemisphereLight, LoopRepeat,
  PerspectiveCamera, Scene, Timer, Vector3, WebGLRenderer,
} from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

const errors = [];

function fail(message) {
  errors.push(String(message));
  document.body.dataset.state = 'error';
  const box = document.getElementById('errors');
  box.textContent = errors.join('\n');
  box.hidden = false;
}

window.addEventListener('error', (e) => fail(e.message));
window.addEventListener('unhandledrejection', (e) => fail(e.reason));

function start() {
  const cfg = JSON.parse(document.getElementById('cloth-usd-data').textContent);
  const bytes = Uint8Array.from(atob(cfg.glb), (c) => c.charCodeAt(0));
  const view = document.getElementById('view');
  const renderer = new WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  view.appendChild(renderer.domElement);

  const scene = new Scene();
  scene.background = new Color(0xe8ebef);
  scene.add(new HemisphereLight(0xffffff, 0x6b6f75, 2.2));
  const sun = new DirectionalLight(0xffffff, 2.0);
  sun.position.set(2, 4, 3);
  scene.add(sun);
  const camera = new PerspectiveCamera(35, 1, 0.01, 200);
  const controls = new OrbitControls(camera, renderer.domElement);

  const slider = document.getElementById('time');
  const label = document.getElementById('label');
  const play = document.getElementById('play');
  const frames = cfg.frames;
  const times = cfg.times; // seconds of each baked frame (a bake may step over time codes)
  const track = cfg.track; // garment centre per frame [m]: the camera follows it
  slider.max = String(frames - 1);
  let mixer = null;
  let action = null;
  let playing = true;
  let frame = 0;
  const timer = new Timer();

  function resize() {
    const w = view.clientWidth || window.innerWidth;
    const h = view.clientHeight || window.innerHeight - 48;
    renderer.setSize(w, h);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
  }

  function follow(f) {
    const c = track[f];
    const moved = new Vector3(c[0], c[1], c[2]).sub(controls.target);
    controls.target.add(moved);
    camera.position.add(moved);
  }

  // The mixer loops: a time at the clip's very end would wrap to its start.
  function seek(f) {
    if (mixer) mixer.setTime(Math.min(times[f], times[frames - 1] - 1e-4));
  }

  function show(f) {
    frame = Math.max(0, Math.min(frames - 1, f));
    slider.value = String(frame);
    label.textContent = `frame ${frame + 1} / ${frames}   time code ${cfg.codes[frame]}`;
    follow(frame);
  }

  play.addEventListener('click', () => {
    playing = !playing;
    play.textContent = playing ? 'Pause' : 'Play';
  });
  slider.addEventListener('input', () => {
    playing = false;
    play.textContent = 'Play';
    const f = Number(slider.value);
    seek(f);
    show(f);
  });
  window.addEventListener('resize', resize);
  resize();

  new GLTFLoader().parse(bytes.buffer, '', (gltf) => {
    // Bounding spheres are computed once, at the rest pose: a skinned body that walks away
    // from it would be culled. The scene is one character: draw it always.
    gltf.scene.traverse((o) => { o.frustumCulled = false; });
    scene.add(gltf.scene);
    const box = new Box3().setFromObject(gltf.scene);
    const size = box.getSize(new Vector3());
    const height = Math.max(size.y, 0.5);
    const c = track[0];
    controls.target.set(c[0], c[1], c[2]);
    camera.position.set(c[0] + height * 0.9, c[1] + height * 0.3, c[2] + height * 2.3);
    const grid = new GridHelper(20, 40, 0x9aa0a6, 0xc4c8cc);
    grid.position.y = cfg.floor;
    scene.add(grid);
    controls.update();
    if (gltf.animations.length) {
      mixer = new AnimationMixer(gltf.scene);
      action = mixer.clipAction(gltf.animations[0]);
      action.setLoop(LoopRepeat, Infinity);
      action.play();
    }
    // #frame=N (1-based, as the timeline shows it): go to that frame, paused, once the
    // first frame is drawn.
    const asked = /frame=(\d+)/.exec(window.location.hash);
    function jump() {
      playing = false;
      play.textContent = 'Play';
      const f = Math.max(0, Math.min(frames - 1, Number(asked[1]) - 1));
      seek(f);
      show(f);
    }
    show(0);
    renderer.setAnimationLoop((now) => {
      timer.update(now);
      const dt = timer.getDelta();
      if (mixer && playing) {
        mixer.update(dt);
        let f = 0;
        while (f + 1 < frames && times[f + 1] <= action.time + 1e-6) f += 1;
        show(f);
      }
      controls.update();
      renderer.render(scene, camera);
      if (document.body.dataset.state === 'loading') {
        document.body.dataset.state = 'ready';
        console.log('cloth-usd preview: ready');
        if (asked) jump();
      }
    });
  }, (err) => fail(`cannot read the embedded glTF: ${err && err.message ? err.message : err}`));
}

try {
  start();
} catch (e) {
  fail(e && e.stack ? e.stack : e);
}
