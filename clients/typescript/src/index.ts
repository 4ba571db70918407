export {
  Client, Session, RemoteError, ValidationError, cameraDoc, mergeChanged,
  type ArrayInput, type Camera, type ClientOptions, type FetchLike, type Fields, type Frame,
  type FrameOptions, type Problem, type ResponseLike, type Vector,
} from "./client.js";
export {
  EXPLAIN_FIELDS, FRAME_FIELDS, REASONS, type Explanation, type FieldName, type FrameArrays,
  type FrameField, type Reason,
} from "./fields.js";
export {
  ARRAY_OF, JSON_TYPE, MSGPACK, NdArray, WireError, decode, encode, fromWire, mediaType, ndarray,
  vectors, type DType, type Encoding, type TypedArray,
} from "./wire.js";
