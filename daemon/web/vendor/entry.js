// The vendor bundle's entry: what the view page (../app.js) imports from three.js and three-vrm.
// Named exports only, so esbuild leaves out the rest of three.js.
export {
  Scene, PerspectiveCamera, WebGLRenderer, Color, HemisphereLight, DirectionalLight, GridHelper,
  Vector3, Quaternion, Mesh, RingGeometry, MeshBasicMaterial, DoubleSide,
} from 'three';
export { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
export { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
export { VRMLoaderPlugin, VRMUtils } from '@pixiv/three-vrm';
