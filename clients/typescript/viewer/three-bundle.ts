// lightsched/three with three.js and the client's NdArray in one ES module
// (dist/viewer/lightsched-three.js), for a page without a bundler; the browser test draws
// with it to check the shader's numbers.
export * from "three";
export * from "../src/three.js";
export { NdArray } from "../src/wire.js";
