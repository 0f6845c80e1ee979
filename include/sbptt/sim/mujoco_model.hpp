#pragma once
/// \file Loading a MuJoCo model (MJCF or URDF) for `MujocoSimulator` (sim/mujoco.hpp): an owned
/// `mjModel`, the file's errors named, MuJoCo's warnings collected instead of printed.
///
/// Opt-in like sim/mujoco.hpp: it includes `<mujoco/mujoco.h>`, and a consumer links the CMake
/// target `sbptt::mujoco`.
#include <atomic>
#include <cctype>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <mujoco/mujoco.h>

#include "sbptt/core/error.hpp"
#include "sbptt/core/input_file.hpp"

namespace sbptt {

/// Deletes an `mjModel` (for `std::unique_ptr` / `std::shared_ptr`).
struct MujocoModelDeleter {
  void operator()(mjModel* model) const { mj_deleteModel(model); }
};

/// An owned `mjModel`.
using MujocoModelPtr = std::unique_ptr<mjModel, MujocoModelDeleter>;

namespace detail {

/// MuJoCo's warning hook, taken over for the duration of one `load_mujoco_model` call that
/// collects its warnings. The hook is one process-wide pointer, so such loads take turns; a
/// warning another thread raises meanwhile goes where it would have gone (the hook that was
/// set, or MuJoCo's own stdout and MUJOCO_LOG.TXT), not into the loader's list.
class MujocoWarningCapture {
public:
  explicit MujocoWarningCapture(std::vector<std::string>& sink) : lock_(shared().mutex) {
    Shared& state = shared();
    state.previous.store(mju_user_warning);
    state.loader.store(std::this_thread::get_id());
    state.sink.store(&sink);
    mju_user_warning = collect;
  }
  MujocoWarningCapture(const MujocoWarningCapture&) = delete;
  MujocoWarningCapture& operator=(const MujocoWarningCapture&) = delete;
  ~MujocoWarningCapture() {
    Shared& state = shared();
    mju_user_warning = state.previous.load();
    state.sink.store(nullptr);
    state.loader.store(std::thread::id{});
  }

private:
  using Hook = void (*)(const char*);
  // Atomic: another thread's warning may read them while a load begins or ends.
  struct Shared {
    std::mutex mutex;
    std::atomic<std::vector<std::string>*> sink{nullptr};
    std::atomic<std::thread::id> loader{};
    std::atomic<Hook> previous{nullptr};
  };
  static Shared& shared() {
    static Shared state;
    return state;
  }
  // Called from MuJoCo's C code: nothing may escape it.
  static void collect(const char* message) noexcept {
    Shared& state = shared();
    std::vector<std::string>* sink = state.sink.load();
    if (sink != nullptr && state.loader.load() == std::this_thread::get_id()) {
      try {
        sink->emplace_back(message);
      } catch (...) {  // out of memory: the warning is lost, not the load
      }
    } else if (const Hook hook = state.previous.load()) {
      hook(message);
    } else {  // what MuJoCo itself does without a hook
      mju_writeLog("WARNING", message);
      std::printf("WARNING: %s\n\n", message);
    }
  }

  std::lock_guard<std::mutex> lock_;
};

}  // namespace detail

/// Parses and compiles the MJCF (or URDF) file `path`. Throws IoError with the system's reason
/// when the file cannot be read (MuJoCo would call any such file "not found") or is a pipe or a
/// device (refused before opening it, which would wait for a writer) or needs more memory than
/// the process may use (MuJoCo's "Could not allocate memory"), InvalidArgument
/// naming the file and quoting MuJoCo's own message when it does not load. With `warnings`, the
/// warnings MuJoCo raises while loading (e.g. "XML contains a 'NaN'") are collected there
/// instead of printed on stdout and appended to MUJOCO_LOG.TXT (`MujocoWarningCapture`);
/// without, they go where MuJoCo sends them.
[[nodiscard]] inline MujocoModelPtr load_mujoco_model(
    const std::string& path, std::vector<std::string>* warnings = nullptr) {
  // MuJoCo opens the model by its name and reads it as a file; a pipe it cannot read, and
  // opening a named pipe waits for a writer for ever.
  std::error_code error;
  const auto type = std::filesystem::status(path, error).type();
  detail::require<IoError>(type != std::filesystem::file_type::fifo &&
                               type != std::filesystem::file_type::character &&
                               type != std::filesystem::file_type::block &&
                               type != std::filesystem::file_type::socket,
                           "load_mujoco_model: '", path, "' is not a regular file (a pipe or a ",
                           "device); expected an MJCF or URDF file");
  (void)detail::open_for_reading(path, "load_mujoco_model: ", "an MJCF or URDF file");
  std::vector<char> message(1000, '\0');
  std::vector<std::string> raised;
  MujocoModelPtr model;
  {
    std::optional<detail::MujocoWarningCapture> capture;
    if (warnings != nullptr) capture.emplace(raised);
    model.reset(
        mj_loadXML(path.c_str(), nullptr, message.data(), static_cast<int>(message.size())));
  }
  if (model == nullptr) {
    std::string reason(message.data());
    while (!reason.empty() && std::isspace(static_cast<unsigned char>(reason.back())) != 0)
      reason.pop_back();
    // Memory is the machine's limit, not a fault of the model: not an InvalidArgument.
    detail::require<IoError>(reason.find("Could not allocate memory") == std::string::npos,
                             "load_mujoco_model: '", path, "' needs more memory than this ",
                             "process may use (MuJoCo: Could not allocate memory)");
    throw InvalidArgument(
        detail::concat("load_mujoco_model: cannot load the model file '", path, "': ", reason));
  }
  if (warnings != nullptr) *warnings = std::move(raised);
  return model;
}

}  // namespace sbptt
