// The C++ client against a real `lightsched serve` it starts (the checkout's .venv, or
// LIGHTSCHED_PYTHON), with an API key:
//   golden       the golden exchanges (schemas/examples) answered byte for byte, and their
//                answers decoded into the arrays their JSON twins hold
//   conformance  every scenario of schemas/conformance (frames equal, problems as named)
//   roundtrip    1k objects over 30 frames: changed_only answers merged equal full frames
#include <arpa/inet.h>
#include <httplib.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "lightsched/client.hpp"

using json = nlohmann::json;
namespace fs = std::filesystem;
using namespace lightsched;

#define CHECK(cond, what)                                                                   \
  do {                                                                                      \
    if (!(cond)) {                                                                          \
      std::ostringstream os_;                                                               \
      os_ << __FILE__ << ":" << __LINE__ << ": " << what << " (" #cond ")";                \
      throw std::runtime_error(os_.str());                                                  \
    }                                                                                       \
  } while (0)

namespace {

const fs::path REPO = LIGHTSCHED_REPO;
const char* KEY = "cpp-key";

class LiveServer {
 public:
  LiveServer() {
    int s = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ::bind(s, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
    socklen_t len = sizeof addr;
    ::getsockname(s, reinterpret_cast<sockaddr*>(&addr), &len);
    port = ntohs(addr.sin_port);
    ::close(s);
    const char* env = std::getenv("LIGHTSCHED_PYTHON");
    const std::string python = env ? env : (REPO / ".venv/bin/python").string();
    const std::string port_s = std::to_string(port);
    pid = ::fork();
    if (pid == 0) {
      ::setenv("LIGHTSCHED_API_KEYS", KEY, 1);
      ::chdir(REPO.c_str());
      ::execl(python.c_str(), python.c_str(), "-m", "lightsched", "serve", "--host", "127.0.0.1",
              "--port", port_s.c_str(), "--no-demo", "--no-warm-up", "--log-level", "warning",
              static_cast<char*>(nullptr));
      std::perror("exec lightsched serve");
      std::_Exit(127);
    }
    url = "http://127.0.0.1:" + port_s;
    httplib::Client probe(url);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    for (;;) {
      int status = 0;
      CHECK(::waitpid(pid, &status, WNOHANG) == 0, "lightsched serve exited");
      if (auto r = probe.Get("/healthz"); r && r->status == 200) break;
      CHECK(std::chrono::steady_clock::now() < deadline, "lightsched serve did not start in 120 s");
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }
  ~LiveServer() {
    ::kill(pid, SIGINT);
    ::waitpid(pid, nullptr, 0);
  }
  int port = 0;
  pid_t pid = -1;
  std::string url;
};

std::string read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  CHECK(in, "cannot read " << p);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

std::vector<std::uint8_t> unbase64(const std::string& text) {
  static const std::string A = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::vector<std::uint8_t> out;
  std::uint32_t acc = 0;
  int bits = 0;
  for (char c : text) {
    if (c == '=') break;
    auto v = A.find(c);
    CHECK(v != std::string::npos, "bad base64");
    acc = (acc << 6) | static_cast<std::uint32_t>(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(static_cast<std::uint8_t>((acc >> bits) & 0xff));
    }
  }
  return out;
}

// A JSON wire array map (base64 data) into an Array.
Array array_of(const json& j) {
  Array a;
  a.dtype = j.at("dtype").get<std::string>();
  a.shape = j.at("shape").get<std::vector<std::int64_t>>();
  a.bytes = unbase64(j.at("data").get<std::string>());
  CHECK(a.bytes.size() == a.size() * a.itemsize(), "array size");
  return a;
}

Fields fields_of(const json& j) {
  Fields f;
  for (const auto& [k, v] : j.items()) f[k] = array_of(v);
  return f;
}

Camera camera_of(const json& j) {
  Camera c{};
  if (j.contains("id")) c.id = j["id"].get<std::int64_t>();
  for (const auto& [name, dst] : {std::pair{"position", c.position}, {"forward", c.forward}, {"up", c.up}}) {
    Array a = array_of(j.at(name));
    std::memcpy(dst, a.bytes.data(), 3 * sizeof(double));
  }
  c.fov_y = j.at("fov_y");
  c.aspect = j.at("aspect");
  c.near_plane = j.at("near");
  c.far_plane = j.at("far");
  if (j.contains("focus")) std::memcpy(c.focus, array_of(j["focus"]).bytes.data(), 2 * sizeof(double));
  if (j.contains("height_px")) c.height_px = j["height_px"];
  return c;
}

std::vector<Camera> cameras_of(const json& j) {
  std::vector<Camera> out;
  for (const auto& c : j) out.push_back(camera_of(c));
  return out;
}

Config config_of(const json& j) {
  Config c;
  if (j.is_null()) return c;
  for (const auto& [k, v] : j.items()) {
    if (v.is_boolean()) c.emplace(k, v.get<bool>());
    else if (v.is_number_integer()) c.emplace(k, v.get<std::int64_t>());
    else if (v.is_number_float()) c.emplace(k, v.get<double>());
    else if (v.is_string()) c.emplace(k, v.get<std::string>());
  }
  return c;
}

std::vector<std::string> outputs_of(const json& j) {
  return j.is_null() ? std::vector<std::string>{} : j.get<std::vector<std::string>>();
}

void check_frame(const Frame& f, const json& expect, const std::string& where) {
  CHECK(f.frame_index == expect.at("frame_index").get<std::int64_t>(), where << ": frame_index");
  for (const auto& [name, wire] : expect.at("arrays").items()) {
    const Array* got = f.get(name);
    CHECK(got != nullptr, where << ": " << name << " missing");
    Array want = array_of(wire);
    CHECK(got->dtype == want.dtype && got->shape == want.shape, where << ": " << name << " dtype or shape");
    CHECK(got->bytes == want.bytes, where << ": " << name << " differs");
  }
}

template <class T>
std::string show(const std::optional<T>& v) {
  if (!v) return "null";
  std::ostringstream os;
  os << *v;
  return os.str();
}

void check_explanation(const Explanation& e, const json& expect, const std::string& where) {
  for (const auto& [name, want] : expect.items()) {
    if (name == "object_id") CHECK(e.object_id == want.get<std::int64_t>(), where << ": object_id");
    else if (name == "frame_index") CHECK(e.frame_index == want.get<std::int64_t>(), where << ": frame_index");
    else if (name == "reason") CHECK(e.reason == want.get<std::vector<std::string>>(), where << ": reason");
    else {
      const Array* got = e.get(name);
      CHECK(got != nullptr, where << ": " << name << " missing");
      Array w = array_of(want);
      CHECK(got->dtype == w.dtype && got->bytes == w.bytes, where << ": " << name << " differs");
    }
  }
}

template <class T>
void outcome(const std::function<T()>& call, void (*check)(const T&, const json&, const std::string&),
             const json& step, const std::string& where) {
  if (step.contains("expect")) {
    check(call(), step["expect"], where);
    return;
  }
  const json& want = step.at("error");
  try {
    call();
  } catch (const RemoteError& e) {
    CHECK(e.status == want.at("status").get<int>(), where << ": status " << e.status << " " << e.what());
    CHECK(e.type == want.at("type").get<std::string>(), where << ": type " << e.type);
    const auto field = want["field"].is_null() ? std::nullopt : std::optional(want["field"].get<std::string>());
    const auto index = want["index"].is_null() ? std::nullopt : std::optional(want["index"].get<std::int64_t>());
    const auto pointer = want["pointer"].is_null() ? std::nullopt : std::optional(want["pointer"].get<std::string>());
    CHECK(e.field == field, where << ": field " << show(e.field));
    CHECK(e.index == index, where << ": index " << show(e.index));
    CHECK(e.pointer == pointer, where << ": pointer " << show(e.pointer));
    CHECK((e.status == 422) == (dynamic_cast<const ValidationError*>(&e) != nullptr), where << ": error class");
    return;
  }
  CHECK(false, where << ": no error");
}

void run_scenario(const json& doc, Client& client, bool stream) {
  std::optional<Session> session;
  int i = 0;
  for (const auto& step : doc.at("steps")) {
    const std::string call = step.at("call");
    const std::string where = doc.at("name").get<std::string>() + " step " + std::to_string(i++) + " (" + call + ")";
    if (call == "session") {
      session.emplace(client.session(config_of(step.at("config")), stream));
    } else if (call == "set_lights") {
      session->set_lights(fields_of(step.at("fields")));
    } else if (call == "update_lights") {
      session->update_lights(fields_of(step.at("fields")));
    } else if (call == "remove_lights") {
      session->remove_lights(array_of(step.at("fields").at("id")));
    } else if (call == "set_objects") {
      session->set_objects(fields_of(step.at("fields")));
    } else if (call == "update_objects") {
      session->update_objects(fields_of(step.at("fields")));
    } else if (call == "remove_objects") {
      session->remove_objects(array_of(step.at("fields").at("id")));
    } else if (call == "frame") {
      FrameOptions o;
      o.dt = step.at("dt");
      o.cut = step.at("cut");
      o.changed_only = step.at("changed_only");
      o.outputs = outputs_of(step.at("outputs"));
      const auto cams = cameras_of(step.at("cameras"));
      outcome<Frame>([&] { return session->frame(cams, o); }, check_frame, step, where);
    } else if (call == "explain") {
      const auto oid = step.at("object_id").get<std::int64_t>();
      outcome<Explanation>([&] { return session->explain(oid); }, check_explanation, step, where);
    } else if (call == "schedule") {
      const auto cams = cameras_of(step.at("cameras"));
      outcome<Frame>([&] {
        return client.schedule(fields_of(step.at("lights")), fields_of(step.at("objects")), cams,
                               config_of(step.at("config")), outputs_of(step.at("outputs")));
      }, check_frame, step, where);
    } else if (call == "info") {
      auto info = session->info();
      for (const auto& [k, v] : step.at("expect").items()) {
        CHECK(info.at(k) == v.get<std::int64_t>(), where << ": " << k);
      }
    } else if (call == "close") {
      session->close();
    } else if (call == "lose") {  // as a dead worker loses it
      client.raw("DELETE", "/v1/sessions/" + session->id(), "");
    } else {
      CHECK(false, where << ": unknown call");
    }
  }
}

void test_golden() {
  LiveServer server;
  Client client(server.url, KEY);
  const fs::path dir = REPO / "schemas/examples";
  const json index = json::parse(read_file(dir / "index.json"));
  std::string sid;
  for (const auto& ex : index) {
    const std::string name = ex.at("name");
    std::string path = ex.at("path");
    if (auto at = path.find("{id}"); at != std::string::npos) path.replace(at, 4, sid);
    auto r = client.raw(ex.at("method"), path, read_file(dir / (name + ".request.msgpack")));
    CHECK(r.status == ex.at("status").get<int>(), name << ": status " << r.status);
    if (name == "session") {
      sid = json::from_msgpack(r.body).at("id");
      continue;
    }
    CHECK(r.body == read_file(dir / (name + ".response.msgpack")), name << ": answer differs from the golden bytes");
    if (r.status != 200) continue;
    const Frame f = decode_frame(r.body).frame;
    const json twin = json::parse(read_file(dir / (name + ".response.json")));
    for (const auto& field : FRAME_FIELDS) {
      if (!twin.contains(field.name)) continue;
      const Array want = array_of(twin[field.name]);
      const Array* got = f.get(field.name);
      CHECK(got && got->dtype == want.dtype && got->shape == want.shape && got->bytes == want.bytes,
            name << ": " << field.name);
    }
  }
}

void test_conformance() {
  LiveServer server;
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(REPO / "schemas/conformance")) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  CHECK(files.size() >= 3, "the suite's scenarios");
  for (const auto& p : files) {
    for (bool stream : {false, true}) {
      Client client(server.url, KEY);
      run_scenario(json::parse(read_file(p)), client, stream);
      std::cout << "  " << p.filename().string() << (stream ? " over the stream" : " over HTTP") << ": ok\n";
    }
  }
}

void test_roundtrip() {
  LiveServer server;
  Client client(server.url, KEY);
  const int n = 1000, l = 60, k = 4;
  std::vector<std::int32_t> ids(n), light_ids(l);
  std::vector<double> lo(3 * n), hi(3 * n), pos(3 * l), radius(l, 40.0);
  for (int i = 0; i < n; i++) {
    ids[i] = 3 * i + 1;
    const double x = (i % 40) * 5.0 - 100.0, z = (i / 40) * 5.0 - 60.0;
    lo[3 * i] = x; lo[3 * i + 1] = 0.0; lo[3 * i + 2] = z;
    hi[3 * i] = x + 3.0; hi[3 * i + 1] = 4.0 + (i % 7); hi[3 * i + 2] = z + 3.0;
  }
  for (int j = 0; j < l; j++) light_ids[j] = j;
  Camera cam{};
  const double p[3] = {-150.0, 80.0, -150.0}, fwd[3] = {1.0, -0.4, 1.0}, up[3] = {0.0, 1.0, 0.0};
  std::memcpy(cam.position, p, sizeof p);
  std::memcpy(cam.forward, fwd, sizeof fwd);
  std::memcpy(cam.up, up, sizeof up);
  cam.fov_y = 1.0; cam.aspect = 16.0 / 9.0; cam.near_plane = 0.5; cam.far_plane = 1000.0;
  Session merged = client.session({{"max_lights", k}});
  Session full = client.session({{"max_lights", k}});
  for (Session* s : {&merged, &full}) {
    s->set_objects({{"id", Array::int32(ids)}, {"bounds_min", Array::vectors(lo)}, {"bounds_max", Array::vectors(hi)}});
  }
  for (int f = 0; f < 30; f++) {
    for (int j = 0; j < l; j++) {
      const double a = 0.05 * f + j;
      pos[3 * j] = 90.0 * std::cos(a); pos[3 * j + 1] = 10.0; pos[3 * j + 2] = 70.0 * std::sin(1.3 * a);
    }
    Fields lights{{"id", Array::int32(light_ids)}, {"position", Array::vectors(pos)}};
    if (f == 0) lights["radius"] = Array::float64(radius);
    for (Session* s : {&merged, &full}) f == 0 ? s->set_lights(lights) : s->update_lights(lights);
    FrameOptions o;
    o.dt = 0.05;
    o.changed_only = true;
    const Frame a = merged.frame({cam}, o);
    o.changed_only = false;
    const Frame b = full.frame({cam}, o);
    CHECK(a.frame_index == f && b.frame_index == f, "frame index");
    for (const auto& field : FRAME_FIELDS) {
      if (std::string(field.name) == "priority") continue;  // held for unchanged rows (wire.md)
      CHECK(a.get(field.name)->bytes == b.get(field.name)->bytes, "frame " << f << ": " << field.name);
    }
    const Array& count = *b.get("count");
    for (std::size_t i = 0; i < count.size(); i++) CHECK(count.data<std::int32_t>()[i] <= k, "count <= K");
  }
  CHECK(merged.info().at("frame_index") == 30, "info");
}

}  // namespace

int main(int argc, char** argv) {
  const std::map<std::string, std::function<void()>> tests = {
      {"golden", test_golden}, {"conformance", test_conformance}, {"roundtrip", test_roundtrip}};
  int failed = 0;
  for (const auto& [name, run] : tests) {
    if (argc > 1 && name != argv[1]) continue;
    try {
      run();
      std::cout << name << ": ok\n";
    } catch (const std::exception& e) {
      std::cout << name << ": FAILED: " << e.what() << "\n";
      failed++;
    }
  }
  return failed ? 1 : 0;
}
