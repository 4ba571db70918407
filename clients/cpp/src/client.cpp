// The C++ client: msgpack-cxx for the wire (schemas/wire.md), cpp-httplib for HTTP,
// Boost.Beast for the WebSocket stream.
#include "lightsched/client.hpp"

#include <httplib.h>

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>

#include <algorithm>
#include <chrono>
#include <msgpack.hpp>
#include <random>
#include <thread>
#include <unordered_map>

namespace lightsched {

namespace {

const std::map<std::string, std::size_t> ITEMSIZE = {
    {"bool", 1},  {"int8", 1},  {"uint8", 1},  {"int16", 2},   {"uint16", 2},  {"int32", 4},
    {"uint32", 4}, {"int64", 8}, {"uint64", 8}, {"float32", 4}, {"float64", 8}};


using Packer = msgpack::packer<msgpack::sbuffer>;

void pack_str(Packer& pk, const std::string& s) {
  pk.pack_str(static_cast<std::uint32_t>(s.size()));
  pk.pack_str_body(s.data(), static_cast<std::uint32_t>(s.size()));
}

void pack_array(Packer& pk, const Array& a) {
  pk.pack_map(3);
  pack_str(pk, "dtype");
  pack_str(pk, a.dtype);
  pack_str(pk, "shape");
  pk.pack_array(static_cast<std::uint32_t>(a.shape.size()));
  for (auto n : a.shape) pk.pack_int64(n);
  pack_str(pk, "data");
  pk.pack_bin(static_cast<std::uint32_t>(a.bytes.size()));
  pk.pack_bin_body(reinterpret_cast<const char*>(a.bytes.data()), static_cast<std::uint32_t>(a.bytes.size()));
}

void pack_vector(Packer& pk, const double* v, std::int64_t n) {
  pack_array(pk, Array::of("float64", {n}, v));
}

void pack_camera(Packer& pk, const Camera& c) {
  pk.pack_map(c.id ? 10 : 9);
  if (c.id) {
    pack_str(pk, "id");
    pk.pack_int64(*c.id);
  }
  pack_str(pk, "position");
  pack_vector(pk, c.position, 3);
  pack_str(pk, "forward");
  pack_vector(pk, c.forward, 3);
  pack_str(pk, "up");
  pack_vector(pk, c.up, 3);
  const std::pair<const char*, double> scalars[] = {
      {"fov_y", c.fov_y}, {"aspect", c.aspect}, {"near", c.near_plane}, {"far", c.far_plane}};
  for (const auto& [name, value] : scalars) {
    pack_str(pk, name);
    pk.pack_double(value);
  }
  pack_str(pk, "focus");
  pack_vector(pk, c.focus, 2);
  pack_str(pk, "height_px");
  pk.pack_double(c.height_px);
}

void pack_cameras(Packer& pk, const std::vector<Camera>& cameras) {
  pk.pack_array(static_cast<std::uint32_t>(cameras.size()));
  for (const auto& c : cameras) pack_camera(pk, c);
}

void pack_fields(Packer& pk, const Fields& fields) {
  pk.pack_map(static_cast<std::uint32_t>(fields.size()));
  for (const auto& [name, a] : fields) {
    pack_str(pk, name);
    pack_array(pk, a);
  }
}

void pack_config(Packer& pk, const Config& config) {
  pk.pack_map(static_cast<std::uint32_t>(config.size()));
  for (const auto& [name, v] : config) {
    pack_str(pk, name);
    switch (v.kind) {
      case ConfigValue::Int: pk.pack_int64(v.i); break;
      case ConfigValue::Float: pk.pack_double(v.f); break;
      case ConfigValue::Bool: v.b ? pk.pack_true() : pk.pack_false(); break;
      case ConfigValue::String: pack_str(pk, v.s); break;
    }
  }
}

void pack_outputs(Packer& pk, const std::vector<std::string>& outputs) {
  pk.pack_array(static_cast<std::uint32_t>(outputs.size()));
  for (const auto& o : outputs) pack_str(pk, o);
}

std::string key_of(const msgpack::object& o) {
  if (o.type != msgpack::type::STR) throw std::runtime_error("malformed answer: a map key is not text");
  return std::string(o.via.str.ptr, o.via.str.size);
}

const msgpack::object* find(const msgpack::object& map, const std::string& key) {
  if (map.type != msgpack::type::MAP) return nullptr;
  for (std::uint32_t i = 0; i < map.via.map.size; i++) {
    const auto& kv = map.via.map.ptr[i];
    if (kv.key.type == msgpack::type::STR && key_of(kv.key) == key) return &kv.val;
  }
  return nullptr;
}

std::int64_t as_int(const msgpack::object& o) {
  if (o.type == msgpack::type::POSITIVE_INTEGER) return static_cast<std::int64_t>(o.via.u64);
  if (o.type == msgpack::type::NEGATIVE_INTEGER) return o.via.i64;
  throw std::runtime_error("malformed answer: an integer expected");
}

// An array map into an Array (a copy: msgpack bins are not aligned).
Array decode_array(const msgpack::object& o) {
  const auto* dtype = find(o, "dtype");
  const auto* shape = find(o, "shape");
  const auto* data = find(o, "data");
  if (!dtype || !shape || !data || o.via.map.size != 3 || dtype->type != msgpack::type::STR ||
      shape->type != msgpack::type::ARRAY || data->type != msgpack::type::BIN) {
    throw std::runtime_error("malformed answer: a bad array map");
  }
  Array a;
  a.dtype = key_of(*dtype);
  for (std::uint32_t i = 0; i < shape->via.array.size; i++) a.shape.push_back(as_int(shape->via.array.ptr[i]));
  if (data->via.bin.size != a.size() * a.itemsize()) throw std::runtime_error("malformed answer: array size");
  a.bytes.assign(data->via.bin.ptr, data->via.bin.ptr + data->via.bin.size);
  return a;
}

std::optional<std::string> opt_str(const msgpack::object& doc, const char* key) {
  const auto* v = find(doc, key);
  if (!v || v->type != msgpack::type::STR) return std::nullopt;
  return key_of(*v);
}

[[noreturn]] void raise_problem(int status, const std::string& body) {
  std::optional<std::string> type, title, detail, field, pointer;
  std::optional<std::int64_t> index;
  try {
    auto handle = msgpack::unpack(body.data(), body.size());
    const auto& doc = handle.get();
    type = opt_str(doc, "type");
    title = opt_str(doc, "title");
    detail = opt_str(doc, "detail");
    field = opt_str(doc, "field");
    pointer = opt_str(doc, "pointer");
    if (const auto* i = find(doc, "index"); i && i->type != msgpack::type::NIL) index = as_int(*i);
    if (const auto* s = find(doc, "status"); s) status = static_cast<int>(as_int(*s));
  } catch (const std::exception&) {
    detail = body;  // not a problem document (a proxy's page, say)
  }
  if (status == 422) {
    throw ValidationError(status, type.value_or(""), title.value_or(""), detail.value_or(""), field, index, pointer);
  }
  throw RemoteError(status, type.value_or(""), title.value_or(""), detail.value_or(""), field, index, pointer);
}

const FrameField* field_of(const std::string& name) {
  for (const auto& f : FRAME_FIELDS) {
    if (name == f.name) return &f;
  }
  return nullptr;
}

template <class T>
void fill_as(Array& a, int value) {
  std::fill(a.data<T>(), a.data<T>() + a.size(), static_cast<T>(value));
}

void fill(Array& a, int value) {
  if (a.itemsize() == 1) std::fill(a.bytes.begin(), a.bytes.end(), static_cast<std::uint8_t>(value));
  else if (a.dtype == "int32") fill_as<std::int32_t>(a, value);
  else if (a.dtype == "float32") fill_as<float>(a, value);
  else if (a.dtype == "float64") fill_as<double>(a, value);
  else if (a.dtype == "int16") fill_as<std::int16_t>(a, value);
  else if (a.dtype == "uint16") fill_as<std::uint16_t>(a, value);
  else if (a.dtype == "uint32") fill_as<std::uint32_t>(a, value);
  else if (a.dtype == "int64") fill_as<std::int64_t>(a, value);
  else fill_as<std::uint64_t>(a, value);
}

// Rows of `wanted` ids in ascending `ids`, -1 where absent.
std::vector<std::int64_t> positions(const Array& ids, const std::int32_t* wanted, std::size_t n) {
  std::vector<std::int64_t> out(n);
  const auto* begin = ids.data<std::int32_t>();
  const auto* end = begin + ids.size();
  for (std::size_t i = 0; i < n; i++) {
    const auto* at = std::lower_bound(begin, end, wanted[i]);
    out[i] = (at != end && *at == wanted[i]) ? at - begin : -1;
  }
  return out;
}

// The service could not be reached (no answer at all): worth sending again.
class Unreachable : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A failure that sending the same request again may get past: no answer, or a proxy with
// no worker for it (502/503/504: the request did not run), or a stream that dropped (503).
bool transient(const std::exception& e) {
  if (const auto* r = dynamic_cast<const RemoteError*>(&e)) {
    return r->status == 502 || r->status == 503 || r->status == 504;
  }
  return dynamic_cast<const Unreachable*>(&e) != nullptr;
}

// The session is gone (404: its worker died, or it idled past the TTL), or the session of
// its id is behind the client (409 out-of-order: a worker taken for dead came back).
bool lost(const std::exception& e) {
  const auto* r = dynamic_cast<const RemoteError*>(&e);
  const std::string suffix = ":out-of-order";
  return r && (r->status == 404 || (r->status == 409 && r->type.size() >= suffix.size() &&
                                    r->type.compare(r->type.size() - suffix.size(), suffix.size(), suffix) == 0));
}

// Pauses between attempts: 0, 25 ms, doubling to 1 s, while `seconds` have not passed.
class Backoff {
 public:
  explicit Backoff(double seconds)
      : end_(std::chrono::steady_clock::now() +
             std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(seconds))) {}
  // Waits before the next attempt; false when the time is up.
  bool next() {
    if (first_) return !(first_ = false);
    pause_ = std::min(1.0, std::max(0.025, 2 * pause_));
    if (std::chrono::steady_clock::now() + std::chrono::duration<double>(pause_) > end_) return false;
    std::this_thread::sleep_for(std::chrono::duration<double>(pause_));
    return true;
  }

 private:
  std::chrono::steady_clock::time_point end_;
  double pause_ = 0.0;
  bool first_ = true;
};

// A random session id: 192 bits, base64url (the service's alphabet).
std::string new_session_id() {
  static const char* ALPHABET = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";
  std::random_device rd;
  std::string out;
  for (int i = 0; i < 32; i++) out += ALPHABET[rd() % 64];
  return out;
}

bool is_float(const std::string& dtype) { return dtype == "float32" || dtype == "float64"; }

double value_at(const Array& a, std::size_t i) {
  const std::string& t = a.dtype;
  if (t == "float64") return a.data<double>()[i];
  if (t == "float32") return a.data<float>()[i];
  if (t == "int32") return a.data<std::int32_t>()[i];
  if (t == "uint32") return a.data<std::uint32_t>()[i];
  if (t == "int64") return static_cast<double>(a.data<std::int64_t>()[i]);
  if (t == "uint64") return static_cast<double>(a.data<std::uint64_t>()[i]);
  if (t == "int16") return a.data<std::int16_t>()[i];
  if (t == "uint16") return a.data<std::uint16_t>()[i];
  if (t == "int8") return a.data<std::int8_t>()[i];
  return a.data<std::uint8_t>()[i];  // uint8, bool
}

// `a` in another dtype (float64 or int64: what a folded update of a different dtype needs).
Array as_dtype(const Array& a, const std::string& dtype) {
  if (a.dtype == dtype) return a;
  Array out{dtype, a.shape, {}};
  out.bytes.resize(out.size() * out.itemsize());
  for (std::size_t i = 0; i < a.size(); i++) {
    if (dtype == "float64") out.data<double>()[i] = value_at(a, i);
    else out.data<std::int64_t>()[i] = static_cast<std::int64_t>(value_at(a, i));
  }
  return out;
}

// Rows `keep` of `a`.
Array take_rows(const Array& a, const std::vector<bool>& keep) {
  Array out{a.dtype, a.shape, {}};
  const std::size_t width = a.row_size() * a.itemsize();
  out.shape[0] = std::count(keep.begin(), keep.end(), true);
  out.bytes.reserve(out.size() * out.itemsize());
  for (std::size_t r = 0; r < keep.size(); r++) {
    if (keep[r]) out.bytes.insert(out.bytes.end(), a.bytes.begin() + r * width, a.bytes.begin() + (r + 1) * width);
  }
  return out;
}

}  // namespace

void SceneMirror::Table::apply(const std::string& op, const Fields& fields) {
  bool known = base.has_value();
  for (const auto& kv : fields) known = known && base->count(kv.first);
  if (op == "set") {
    base = fields;
    calls.clear();
  } else if (!known || !calls.empty()) {
    calls.push_back({op, fields});
  } else if (op == "remove") {
    const Array& ids = base->at("id");
    std::vector<double> gone;
    for (std::size_t i = 0; i < fields.at("id").size(); i++) gone.push_back(value_at(fields.at("id"), i));
    std::vector<bool> keep(ids.size());
    for (std::size_t r = 0; r < ids.size(); r++) {
      keep[r] = std::find(gone.begin(), gone.end(), value_at(ids, r)) == gone.end();
    }
    for (auto& kv : *base) kv.second = take_rows(kv.second, keep);
  } else {
    std::unordered_map<double, std::size_t> row_of;
    const Array& ids = base->at("id");
    for (std::size_t r = 0; r < ids.size(); r++) row_of[value_at(ids, r)] = r;
    const Array& upd_ids = fields.at("id");
    for (const auto& [name, given] : fields) {
      Array value = given;
      Array& old = base->at(name);
      if (old.dtype != value.dtype) {
        const std::string to = is_float(old.dtype) || is_float(value.dtype) ? "float64" : "int64";
        old = as_dtype(old, to);
        value = as_dtype(value, to);
      }
      const std::size_t width = old.row_size() * old.itemsize();
      for (std::size_t i = 0; i < upd_ids.size(); i++) {
        std::memcpy(&old.bytes[row_of.at(value_at(upd_ids, i)) * width], &value.bytes[i * width], width);
      }
    }
  }
}

void SceneMirror::apply(const std::vector<Change>& changes) {
  for (const auto& c : changes) {
    const auto cut = c.op.find('_');
    const std::string op = c.op.substr(0, cut), kind = c.op.substr(cut + 1);
    (kind == "lights" ? lights_ : objects_).apply(op, c.fields);
  }
}

std::vector<Change> SceneMirror::replay() const {
  std::vector<Change> out;
  for (const auto& [kind, table] : {std::pair<std::string, const Table*>{"lights", &lights_},
                                    std::pair<std::string, const Table*>{"objects", &objects_}}) {
    if (table->base) out.push_back({"set_" + kind, *table->base});
    for (const auto& c : table->calls) out.push_back({c.op + "_" + kind, c.fields});
  }
  return out;
}

std::size_t Array::size() const {
  std::size_t n = 1;
  for (auto s : shape) n *= static_cast<std::size_t>(s);
  return n;
}

std::size_t Array::itemsize() const {
  auto it = ITEMSIZE.find(dtype);
  if (it == ITEMSIZE.end()) throw std::invalid_argument("unknown dtype " + dtype);
  return it->second;
}

std::size_t Array::row_size() const {
  std::size_t n = 1;
  for (std::size_t i = 1; i < shape.size(); i++) n *= static_cast<std::size_t>(shape[i]);
  return n;
}

RemoteError::RemoteError(int status_, std::string type_, std::string title_, std::string detail_,
                         std::optional<std::string> field_, std::optional<std::int64_t> index_,
                         std::optional<std::string> pointer_)
    : std::runtime_error(std::to_string(status_) + " " + title_ + ": " + detail_),
      status(status_), type(std::move(type_)), title(std::move(title_)), detail(std::move(detail_)),
      field(std::move(field_)), index(index_), pointer(std::move(pointer_)) {}

Answer decode_frame(const std::string& bytes) {
  auto handle = msgpack::unpack(bytes.data(), bytes.size());
  const auto& doc = handle.get();
  if (doc.type != msgpack::type::MAP) throw std::runtime_error("malformed answer: not a map");
  Answer out;
  for (std::uint32_t i = 0; i < doc.via.map.size; i++) {
    const auto& kv = doc.via.map.ptr[i];
    const std::string key = key_of(kv.key);
    if (key == "frame_index") out.frame.frame_index = as_int(kv.val);
    else if (key == "changed_only") out.changed_only = kv.val.type == msgpack::type::BOOLEAN && kv.val.via.boolean;
    else if (key == "rows") out.rows = decode_array(kv.val);
    else if (field_of(key) != nullptr) out.frame.arrays[key] = decode_array(kv.val);
  }
  out.has_object_id = out.frame.arrays.count("object_id") > 0;
  return out;
}

Explanation decode_explanation(const std::string& bytes) {
  auto handle = msgpack::unpack(bytes.data(), bytes.size());
  const auto& doc = handle.get();
  if (doc.type != msgpack::type::MAP) throw std::runtime_error("malformed answer: not a map");
  Explanation out;
  for (std::uint32_t i = 0; i < doc.via.map.size; i++) {
    const auto& kv = doc.via.map.ptr[i];
    const std::string key = key_of(kv.key);
    if (key == "object_id") out.object_id = as_int(kv.val);
    else if (key == "frame_index") out.frame_index = as_int(kv.val);
    else if (key == "reason" && kv.val.type == msgpack::type::ARRAY) {
      for (std::uint32_t j = 0; j < kv.val.via.array.size; j++) out.reason.push_back(key_of(kv.val.via.array.ptr[j]));
    } else if (kv.val.type == msgpack::type::MAP && find(kv.val, "dtype")) {
      out.columns[key] = decode_array(kv.val);
    }
  }
  return out;
}

std::map<std::string, Array> decode_arrays(const std::string& bytes) {
  auto handle = msgpack::unpack(bytes.data(), bytes.size());
  const auto& doc = handle.get();
  if (doc.type != msgpack::type::MAP) throw std::runtime_error("malformed: not a map");
  std::map<std::string, Array> out;
  for (std::uint32_t i = 0; i < doc.via.map.size; i++) {
    const auto& kv = doc.via.map.ptr[i];
    if (kv.val.type == msgpack::type::MAP && find(kv.val, "dtype")) out[key_of(kv.key)] = decode_array(kv.val);
  }
  return out;
}

Frame merge_changed(const Frame* prev, const Frame& answer, const Array& rows, bool has_object_id) {
  const Array* prev_ids = prev ? prev->get("object_id") : nullptr;
  const bool same_set = !has_object_id && prev_ids != nullptr;
  Frame f;
  f.frame_index = answer.frame_index;
  Array ids = same_set ? *prev_ids : (has_object_id ? *answer.get("object_id") : Array::int32({}));
  const auto at = positions(ids, rows.data<std::int32_t>(), rows.size());
  std::vector<std::int64_t> kept;
  if (!same_set && prev_ids) kept = positions(*prev_ids, ids.data<std::int32_t>(), ids.size());
  for (const auto& [name, part] : answer.arrays) {
    const FrameField* field = field_of(name);
    if (name == "object_id") continue;
    if (!field->per_object) {
      f.arrays[name] = part;
      continue;
    }
    const std::size_t width = part.row_size() * part.itemsize();
    const Array* old = prev ? prev->get(name) : nullptr;
    Array full;
    if (same_set && old) {
      full = *old;
    } else {
      full.dtype = part.dtype;
      full.shape = part.shape;
      full.shape[0] = static_cast<std::int64_t>(ids.size());
      full.bytes.resize(full.size() * full.itemsize());
      fill(full, field->empty);
      if (old) {
        for (std::size_t i = 0; i < kept.size(); i++) {
          if (kept[i] >= 0) std::memcpy(&full.bytes[i * width], &old->bytes[kept[i] * width], width);
        }
      }
    }
    for (std::size_t r = 0; r < at.size(); r++) {
      std::memcpy(&full.bytes[at[r] * width], &part.bytes[r * width], width);
    }
    f.arrays[name] = std::move(full);
  }
  f.arrays["object_id"] = std::move(ids);
  return f;
}

struct Client::Http {
  explicit Http(const std::string& url) : cli(url) {
    cli.set_keep_alive(true);
    cli.set_tcp_nodelay(true);  // else Nagle holds the body behind the headers: +40 ms
    cli.set_read_timeout(600, 0);
  }
  httplib::Client cli;
};

Client::Client(const std::string& url, std::string api_key)
    : http_(std::make_unique<Http>(url)), url_(url), api_key_(std::move(api_key)) {}

Client::~Client() = default;

Client::Raw Client::raw(const std::string& method, const std::string& path, const std::string& body,
                        const std::string& content_type) {
  httplib::Request req;
  req.method = method;
  req.path = path;
  req.headers = {{"Accept", content_type}};
  if (!api_key_.empty()) req.headers.emplace("Authorization", "Bearer " + api_key_);
  if (!body.empty()) {
    req.body = body;
    req.headers.emplace("Content-Type", content_type);
  }
  auto res = http_->cli.send(req);
  if (!res) throw Unreachable("request to the service failed: " + httplib::to_string(res.error()));
  return {res->status, res->get_header_value("Content-Type"), res->body};
}

std::string Client::call(const std::string& method, const std::string& path, const std::string& body) {
  Raw r = raw(method, path, body);
  if (r.status >= 400) raise_problem(r.status, r.body);
  return r.body;
}

std::string Client::call_retrying(const std::string& method, const std::string& path, const std::string& body) {
  Backoff backoff(retry_seconds);
  for (;;) {
    try {
      return call(method, path, body);
    } catch (const std::exception& e) {
      if (!transient(e) || !backoff.next()) throw;
    }
  }
}

namespace {
// The frame_index of a session answer (PUT, GET).
std::int64_t frame_index_of(const std::string& body, std::string* id = nullptr) {
  auto handle = msgpack::unpack(body.data(), body.size());
  const auto* sid = find(handle.get(), "id");
  const auto* index = find(handle.get(), "frame_index");
  if (!sid || !index) throw std::runtime_error("malformed answer: no session id");
  if (id) *id = key_of(*sid);
  return as_int(*index);
}
}  // namespace

Session Client::session(const Config& config, bool stream, const std::string& id) {
  msgpack::sbuffer buf;
  Packer pk(&buf);
  pk.pack_map(1);
  pack_str(pk, "config");
  pack_config(pk, config);
  std::string body(buf.data(), buf.size());
  std::string sid = id.empty() ? new_session_id() : id;
  const auto index = frame_index_of(call_retrying("PUT", "/v1/sessions/" + sid, body), &sid);
  return Session(this, sid, index, stream, std::move(body));
}

Frame Client::schedule(const Fields& lights, const Fields& objects, const std::vector<Camera>& cameras,
                       const Config& config, const std::vector<std::string>& outputs) {
  msgpack::sbuffer buf;
  Packer pk(&buf);
  pk.pack_map(3 + (config.empty() ? 0 : 1) + (outputs.empty() ? 0 : 1));
  pack_str(pk, "lights");
  pack_fields(pk, lights);
  pack_str(pk, "objects");
  pack_fields(pk, objects);
  pack_str(pk, "cameras");
  pack_cameras(pk, cameras);
  if (!config.empty()) {
    pack_str(pk, "config");
    pack_config(pk, config);
  }
  if (!outputs.empty()) {
    pack_str(pk, "outputs");
    pack_outputs(pk, outputs);
  }
  return decode_frame(call("POST", "/v1/schedule", std::string(buf.data(), buf.size()))).frame;
}

Frame Session::frame(const std::vector<Camera>& cameras, const FrameOptions& options) {
  std::vector<Change> own;
  own.swap(changes_);
  auto request = [&](const std::vector<Change>& changes, bool cut, std::int64_t seq) {
    msgpack::sbuffer buf;
    Packer pk(&buf);
    pk.pack_map(5 + (options.outputs.empty() ? 0 : 1) + (options.changed_only ? 1 : 0) + (options.stats ? 0 : 1));
    pack_str(pk, "dt");
    pk.pack_double(options.dt);
    pack_str(pk, "cut");
    cut ? pk.pack_true() : pk.pack_false();
    pack_str(pk, "cameras");
    pack_cameras(pk, cameras);
    pack_str(pk, "changes");
    pk.pack_array(static_cast<std::uint32_t>(changes.size()));
    for (const auto& c : changes) {
      pk.pack_map(2);
      pack_str(pk, "op");
      pack_str(pk, c.op);
      pack_str(pk, "fields");
      pack_fields(pk, c.fields);
    }
    pack_str(pk, "seq");
    pk.pack_int64(seq);
    if (!options.outputs.empty()) {
      pack_str(pk, "outputs");
      pack_outputs(pk, options.outputs);
    }
    if (options.changed_only) {
      pack_str(pk, "changed_only");
      pk.pack_true();
    }
    if (!options.stats) {
      pack_str(pk, "stats");
      pk.pack_false();
    }
    return std::string(buf.data(), buf.size());
  };
  std::string body = request(own, options.cut, frame_index_);
  std::string answered;
  // Sent again while the service cannot be reached (its seq keeps it from running twice);
  // a lost session is made again and given the mirrored scene, then this frame's own
  // changes, as a cut.
  Backoff backoff(client_->retry_seconds);
  for (;;) {
    try {
      answered = send(body);
      break;
    } catch (const std::exception& e) {
      const bool gone = lost(e) && !closed_;
      if ((!gone && !transient(e)) || !backoff.next()) throw;
      ws_.reset();
      if (gone) {
        frame_index_ = remake();
        std::vector<Change> changes = mirror_.replay();
        changes.insert(changes.end(), own.begin(), own.end());
        body = request(changes, true, frame_index_);
        last_.reset();
        recoveries_++;
      }
    }
  }
  mirror_.apply(own);
  auto answer = decode_frame(answered);
  Frame f = answer.changed_only ? merge_changed(last_ ? &*last_ : nullptr, answer.frame, answer.rows, answer.has_object_id)
                                : std::move(answer.frame);
  last_ = f;
  frame_index_ = f.frame_index + 1;
  return f;
}

std::string Session::send(const std::string& request) {
  return stream_ ? stream_call(request) : client_->call("POST", "/v1/sessions/" + id_ + "/frames", request);
}

std::int64_t Session::remake() {
  const std::string path = "/v1/sessions/" + id_;
  try {
    client_->call("DELETE", path, "");  // a stale copy, if a worker came back with one
  } catch (const RemoteError&) {
  }
  return frame_index_of(client_->call_retrying("PUT", path, body_));
}

std::map<std::string, std::int64_t> Session::info() {
  auto body = client_->call("GET", "/v1/sessions/" + id_, "");
  auto handle = msgpack::unpack(body.data(), body.size());
  std::map<std::string, std::int64_t> out;
  for (const char* key : {"frame_index", "lights", "objects"}) {
    if (const auto* v = find(handle.get(), key)) out[key] = as_int(*v);
  }
  return out;
}

Explanation Session::explain(std::int64_t object_id) {
  return decode_explanation(
      client_->call("GET", "/v1/sessions/" + id_ + "/objects/" + std::to_string(object_id) + "/explain", ""));
}

namespace beast = boost::beast;
namespace websocket = boost::beast::websocket;
using tcp = boost::asio::ip::tcp;

struct Session::Stream {
  boost::asio::io_context ioc;
  websocket::stream<tcp::socket> ws{ioc};
  beast::flat_buffer buffer;
};

std::string Session::stream_call(const std::string& request) {
  try {
    if (!ws_) {
      // url_ is "http://host:port" (or https, which this stream does not speak).
      const std::string& url = client_->url_;
      const auto scheme_end = url.find("://");
      const std::string rest = scheme_end == std::string::npos ? url : url.substr(scheme_end + 3);
      const std::string authority = rest.substr(0, rest.find('/'));
      const auto colon = authority.rfind(':');
      const std::string host = colon == std::string::npos ? authority : authority.substr(0, colon);
      const std::string port = colon == std::string::npos ? "80" : authority.substr(colon + 1);
      auto s = std::make_shared<Stream>();
      tcp::resolver resolver(s->ioc);
      boost::asio::connect(s->ws.next_layer(), resolver.resolve(host, port));
      s->ws.next_layer().set_option(tcp::no_delay(true));  // one small message each way
      s->ws.read_message_max(0);  // the service's limit applies, not Beast's 16 MB default
      const std::string key = client_->api_key_;
      s->ws.set_option(websocket::stream_base::decorator([key](websocket::request_type& req) {
        if (!key.empty()) req.set(beast::http::field::authorization, "Bearer " + key);
      }));
      s->ws.handshake(authority, "/v1/sessions/" + id_ + "/stream");
      s->ws.binary(true);
      ws_ = std::move(s);
    }
    ws_->ws.write(boost::asio::buffer(request));
    ws_->buffer.clear();
    ws_->ws.read(ws_->buffer);
  } catch (const boost::system::system_error& e) {
    // A refused handshake or a closed stream (1009: a message over the service's limit).
    // No close frame (the worker or the connection died), or going away / restarting: a
    // 503, worth sending again; 1009: a message over the service's limit (413).
    const auto code = ws_ ? static_cast<int>(ws_->ws.reason().code) : 0;
    const std::string reason = ws_ ? std::string(ws_->ws.reason().reason.c_str()) : "";
    ws_.reset();
    const int status = code == websocket::close_code::too_big ? 413
                       : (code == 0 || code == 1001 || code == 1011 || code == 1012) ? 503 : 400;
    throw RemoteError(status, "", "Stream closed", "the stream failed: " + std::string(e.what()) +
                                                       (reason.empty() ? "" : " (" + reason + ")"),
                      std::nullopt, std::nullopt, std::nullopt);
  }
  std::string answer = beast::buffers_to_string(ws_->buffer.data());
  // A problem document instead of a frame (a refusal, or a handshake the service refused).
  auto handle = msgpack::unpack(answer.data(), answer.size());
  if (!find(handle.get(), "frame_index")) raise_problem(400, answer);
  return answer;
}

void Session::close() {
  closed_ = true;
  if (ws_) {
    boost::system::error_code ignored;
    ws_->ws.close(websocket::close_code::normal, ignored);
    ws_.reset();
  }
  client_->call("DELETE", "/v1/sessions/" + id_, "");
}

}  // namespace lightsched
