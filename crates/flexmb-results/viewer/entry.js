// Entry of the three.js bundle embedded in flexmb's HTML animation: puts the whole of
// three.js on `window.THREE` and its OrbitControls on `window.OrbitControls`, so that the
// viewer (viewer.js, a classic script) needs no modules. Built by build.sh.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

window.THREE = THREE;
window.OrbitControls = OrbitControls;
