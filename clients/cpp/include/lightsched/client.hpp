// The LightSched client for native engines (C++17): the embedded lightsched API over the
// service's HTTP/msgpack wire (schemas/wire.md). A Client makes sessions and runs the
// stateless schedule(); a Session holds scene changes until frame(), which sends them with
// the frame. Frames come back as flat little-endian arrays an engine can upload as they are
// (Array::data<T>()), changed_only answers merged into the session's last frame.
#pragma once

#include <cstdint>
#include <cstring>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "lightsched/fields.hpp"

namespace lightsched {

// A numeric array: prod(shape) values of dtype, row-major, in `bytes` (16-byte aligned).
struct Array {
  std::string dtype;  // bool, int8, uint8, int16, uint16, int32, uint32, int64, uint64, float32, float64
  std::vector<std::int64_t> shape;
  std::vector<std::uint8_t> bytes;

  std::size_t size() const;       // prod(shape)
  std::size_t itemsize() const;   // bytes per value
  std::size_t row_size() const;   // values per row (prod(shape[1:]))
  template <class T> const T* data() const { return reinterpret_cast<const T*>(bytes.data()); }
  template <class T> T* data() { return reinterpret_cast<T*>(bytes.data()); }

  template <class T> static Array of(const std::string& dtype, const std::vector<std::int64_t>& shape,
                                     const T* values) {
    Array a{dtype, shape, {}};
    a.bytes.resize(a.size() * sizeof(T));
    if (!a.bytes.empty()) std::memcpy(a.bytes.data(), values, a.bytes.size());
    return a;
  }
  static Array int32(const std::vector<std::int32_t>& v) { return of("int32", {std::int64_t(v.size())}, v.data()); }
  static Array float64(const std::vector<double>& v) { return of("float64", {std::int64_t(v.size())}, v.data()); }
  // n 3-vectors from 3n values (positions, directions, box corners).
  static Array vectors(const std::vector<double>& v) { return of("float64", {std::int64_t(v.size() / 3), 3}, v.data()); }
  static Array bools(const std::vector<std::uint8_t>& v) { return of("bool", {std::int64_t(v.size())}, v.data()); }
};

// The keyword arrays of a scene call (DESIGN section 7), by field name.
using Fields = std::map<std::string, Array>;

// A view (DESIGN section 1); without an id a camera takes its position in the list.
struct Camera {
  std::optional<std::int64_t> id;
  double position[3];
  double forward[3];
  double up[3];
  double fov_y;
  double aspect;
  double near_plane;
  double far_plane;
  double focus[2] = {0.0, 0.0};
  double height_px = 1080.0;
};

// A frame (DESIGN section 3): the arrays asked for, by name, always whole.
struct Frame {
  std::int64_t frame_index = 0;
  std::map<std::string, Array> arrays;
  const Array* get(const std::string& name) const {
    auto it = arrays.find(name);
    return it == arrays.end() ? nullptr : &it->second;
  }
};

// Scheduler.explain's answer (DESIGN section 7): one row per light, in ascending light id.
// columns: light_id, priority, selection_priority, d2, slot, fade_weight, fade_state (the
// EXPLAIN_FIELDS of schemas/frame_fields.json; NaN or -1 where a value does not exist);
// reason: the first reason that applies to each row.
struct Explanation {
  std::int64_t object_id = 0;
  std::int64_t frame_index = 0;
  std::map<std::string, Array> columns;
  std::vector<std::string> reason;
  const Array* get(const std::string& name) const {
    auto it = columns.find(name);
    return it == columns.end() ? nullptr : &it->second;
  }
};

struct FrameOptions {
  double dt = 1.0 / 60.0;
  bool cut = false;
  std::vector<std::string> outputs;  // empty: all
  bool changed_only = false;
  bool stats = true;
};

// A config value (DESIGN section 1's Config fields): a number, a bool or a string.
struct ConfigValue {
  enum Kind { Int, Float, Bool, String } kind;
  std::int64_t i = 0;
  double f = 0.0;
  bool b = false;
  std::string s;
  ConfigValue(int v) : kind(Int), i(v) {}
  ConfigValue(std::int64_t v) : kind(Int), i(v) {}
  ConfigValue(double v) : kind(Float), f(v) {}
  ConfigValue(bool v) : kind(Bool), b(v) {}
  ConfigValue(const char* v) : kind(String), s(v) {}
  ConfigValue(std::string v) : kind(String), s(std::move(v)) {}
};
using Config = std::map<std::string, ConfigValue>;

// The service refused a call: the problem document's status, type, field, index, pointer.
class RemoteError : public std::runtime_error {
 public:
  RemoteError(int status, std::string type, std::string title, std::string detail,
              std::optional<std::string> field, std::optional<std::int64_t> index,
              std::optional<std::string> pointer);
  int status;
  std::string type, title, detail;
  std::optional<std::string> field;
  std::optional<std::int64_t> index;
  std::optional<std::string> pointer;
};

// Bad input (422): field and index as lightsched.ValidationError names them.
class ValidationError : public RemoteError {
 public:
  using RemoteError::RemoteError;
};

struct Change {
  std::string op;
  Fields fields;
};

// The full frame from a changed_only answer and the last full frame (wire.md).
Frame merge_changed(const Frame* prev, const Frame& answer, const Array& rows, bool has_object_id);

class Client;

// The scene a session holds, as far as the client gave it: the changes of every frame the
// service answered, so that a session lost with its worker (the service answers 404) is
// rebuilt on the worker that owns its id now. Per kind (lights, objects): the last set_
// call's arrays with later updates and removals folded in; an update naming a field the
// set_ did not give (whose default may derive from other fields) is kept as a call of its
// own, and so is everything after it, until the next set_ (the Python and TypeScript
// clients' rule).
class SceneMirror {
 public:
  void apply(const std::vector<Change>& changes);
  // The changes that rebuild the scene in an empty session.
  std::vector<Change> replay() const;

 private:
  struct Table {
    std::optional<Fields> base;
    std::vector<Change> calls;  // op without its kind: "update", "remove"
    void apply(const std::string& op, const Fields& fields);
  };
  Table lights_, objects_;
};

// A session: lightsched.Scheduler's calls, computed by the service. Every frame carries a
// sequence number (seq): a frame whose answer was lost (a broken connection, a 502/503
// from a load balancer while a worker is replaced) is sent again without running twice,
// for up to Client::retry_seconds; a lost session is rebuilt from its mirror within the
// frame, which then counts as a cut (recoveries() counts those).
class Session {
 public:
  const std::string& id() const { return id_; }
  std::int64_t frame_index() const { return frame_index_; }

  void set_lights(Fields fields) { changes_.push_back({"set_lights", std::move(fields)}); }
  void update_lights(Fields fields) { changes_.push_back({"update_lights", std::move(fields)}); }
  void remove_lights(Array id) { changes_.push_back({"remove_lights", {{"id", std::move(id)}}}); }
  void set_objects(Fields fields) { changes_.push_back({"set_objects", std::move(fields)}); }
  void update_objects(Fields fields) { changes_.push_back({"update_objects", std::move(fields)}); }
  void remove_objects(Array id) { changes_.push_back({"remove_objects", {{"id", std::move(id)}}}); }

  // The held changes, then one frame (the changes are sent either way: a refused frame
  // changes nothing in the session).
  Frame frame(const std::vector<Camera>& cameras, const FrameOptions& options = {});
  // Why each light is (not) on the object in the last frame.
  Explanation explain(std::int64_t object_id);
  // frame_index, lights and objects of the session.
  std::map<std::string, std::int64_t> info();
  // Closes the stream, if open, and deletes the session.
  void close();
  // Frames go over the session's WebSocket stream (Boost.Beast) instead of HTTP.
  bool stream() const { return stream_; }
  // Times the session was rebuilt (its worker died).
  int recoveries() const { return recoveries_; }

 private:
  friend class Client;
  Session(Client* client, std::string id, std::int64_t frame_index, bool stream, std::string body)
      : client_(client), id_(std::move(id)), frame_index_(frame_index), stream_(stream),
        body_(std::move(body)) {}
  std::string stream_call(const std::string& request);
  std::string send(const std::string& request);
  std::int64_t remake();
  Client* client_;
  std::string id_;
  std::int64_t frame_index_;
  bool stream_;
  std::string body_;  // the PUT body that makes the session (its config)
  SceneMirror mirror_;
  int recoveries_ = 0;
  bool closed_ = false;
  std::vector<Change> changes_;
  std::optional<Frame> last_;
  // The stream, opened by the first frame (copies of a Session share it).
  struct Stream;
  std::shared_ptr<Stream> ws_;
};

class Client {
 public:
  // url: "http://host:port"; api_key: sent as "Authorization: Bearer <key>" when set.
  explicit Client(const std::string& url, std::string api_key = "");
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  // A session of this id (or of a new random one when empty), made with PUT: a load
  // balancer routes by the id, and a retried PUT is safe. With stream, its frames go over
  // its WebSocket (one connection, opened by the first frame; the key is sent in the
  // handshake's Authorization header).
  Session session(const Config& config = {}, bool stream = false, const std::string& id = "");
  // How long a frame is sent again while the service cannot be reached.
  double retry_seconds = 10.0;
  // The stateless one-frame call (lightsched.schedule).
  Frame schedule(const Fields& lights, const Fields& objects, const std::vector<Camera>& cameras,
                 const Config& config = {}, const std::vector<std::string>& outputs = {});
  // One raw call: msgpack body in, (status, content type, body) out, no decoding.
  struct Raw {
    int status;
    std::string content_type;
    std::string body;
  };
  Raw raw(const std::string& method, const std::string& path, const std::string& body,
          const std::string& content_type = "application/msgpack");

 private:
  friend class Session;
  std::string call(const std::string& method, const std::string& path, const std::string& body);
  // call(), sent again while it fails transiently: only for requests safe to repeat.
  std::string call_retrying(const std::string& method, const std::string& path, const std::string& body);
  struct Http;
  std::unique_ptr<Http> http_;
  std::string url_;
  std::string api_key_;
};

// The wire codec (exposed for the tests): a frame answer's bytes into a Frame (and, for
// changed_only, its rows).
struct Answer {
  Frame frame;
  bool changed_only = false;
  bool has_object_id = false;
  Array rows;
};
Answer decode_frame(const std::string& msgpack_bytes);
Explanation decode_explanation(const std::string& msgpack_bytes);
// A msgpack map of array maps into Arrays by key (other values are skipped).
std::map<std::string, Array> decode_arrays(const std::string& msgpack_bytes);

}  // namespace lightsched
