export {
  Client, Session, RemoteError, ValidationError, cameraDoc, mergeChanged,
  type ArrayInput, type Camera, type ClientOptions, type Fields, type Frame, type FrameOptions,
  type Problem, type Vector,
} from "./client.js";
export { FRAME_FIELDS, type FieldName, type FrameArrays, type FrameField } from "./fields.js";
export {
  ARRAY_OF, JSON_TYPE, MSGPACK, NdArray, WireError, decode, encode, fromWire, mediaType, ndarray,
  vectors, type DType, type Encoding, type TypedArray,
} from "./wire.js";
