// One client's side of bench/clients.py: a session of the scene in SCENE (a msgpack map of
// arrays that bench/clients.py writes), then frames in which every light moves, each timed
// from the update_lights call to the decoded frame. Prints {"ms": [...]} on stdout.
//   bench_roundtrip URL SCENE [http|stream]
#include <chrono>
#include <cstring>
#include <fstream>
#include <iostream>
#include <iterator>

#include "lightsched/client.hpp"

using namespace lightsched;

int main(int argc, char** argv) {
  if (argc != 3 && argc != 4) {
    std::cerr << "usage: bench_roundtrip URL SCENE [http|stream]\n";
    return 2;
  }
  const bool stream = argc == 4 && std::string(argv[3]) == "stream";
  std::ifstream in(argv[2], std::ios::binary);
  auto scene = decode_arrays(std::string(std::istreambuf_iterator<char>(in), {}));
  Fields lights, objects;
  for (auto& [key, a] : scene) {
    if (key.rfind("lights.", 0) == 0) lights[key.substr(7)] = a;
    if (key.rfind("objects.", 0) == 0) objects[key.substr(8)] = a;
  }
  const double* c = scene.at("camera").data<double>();
  Camera cam{};
  std::memcpy(cam.position, c, 3 * sizeof(double));
  std::memcpy(cam.forward, c + 3, 3 * sizeof(double));
  std::memcpy(cam.up, c + 6, 3 * sizeof(double));
  cam.fov_y = c[9]; cam.aspect = c[10]; cam.near_plane = c[11]; cam.far_plane = c[12];
  const Array& positions = scene.at("positions");
  const std::int64_t warmup = scene.at("warmup").data<std::int64_t>()[0];
  const std::int64_t frames = scene.at("frames").data<std::int64_t>()[0];
  const std::int64_t k = scene.at("max_lights").data<std::int64_t>()[0];
  const std::int64_t poses = positions.shape[0], l = positions.shape[1];

  Client client(argv[1]);
  Session s = client.session({{"max_lights", k}}, stream);
  s.set_lights(lights);
  s.set_objects(objects);
  s.frame({cam});
  std::cout << "{\"ms\": [";
  for (std::int64_t i = 0; i < warmup + frames; i++) {
    const auto t0 = std::chrono::steady_clock::now();
    s.update_lights({{"id", lights.at("id")},
                     {"position", Array::of("float64", {l, 3}, positions.data<double>() + (i % poses) * l * 3)}});
    Frame f = s.frame({cam});
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    if (f.get("light_ids") == nullptr) return 1;
    if (i >= warmup) std::cout << (i > warmup ? ", " : "") << ms;
  }
  std::cout << "]}\n";
  s.close();
  return 0;
}
