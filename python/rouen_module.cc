// The `rouen` Python module: a second front end over the pipeline library (as app/ is the
// first). It parses no command line and prints nothing; progress goes to an optional Python
// callable, errors raise rouen.Error with the library's message.
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <atomic>
#include <cmath>
#include <csignal>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/cancel.h"
#include "core/error.h"
#include "core/image.h"
#include "core/lens.h"
#include "core/session.h"
#include "core/time.h"
#include "core/version.h"
#include "pipeline/render_scene.h"
#include "pipeline/scene.h"
#include "pipeline/solve_config.h"
#include "pipeline/status.h"
#include "pipeline/validate.h"

namespace py = pybind11;

namespace rouen {
namespace {

using Log = std::function<void(const std::string&)>;

// Python objects from JSON through Python's own json module: one conversion, no second
// printer of the library's structures.
py::object ToPython(const nlohmann::json& j) {
  return py::module_::import("json").attr("loads")(j.dump());
}

// Throws rouen::Error naming the key of the first number in `o` (dicts and lists within) that
// is not finite: JSON has no NaN, and json.dumps would write one that no parser reads.
void CheckFinite(const py::handle& o, const std::string& where) {
  if (py::isinstance<py::float_>(o)) {
    const double v = o.cast<double>();
    if (!std::isfinite(v))
      throw Error(where + " = " + std::string(py::str(o)) + " is not a finite number");
  } else if (py::isinstance<py::dict>(o)) {
    for (const auto& [k, v] : o.cast<py::dict>())
      CheckFinite(v, (where.empty() ? "" : where + ".") + std::string(py::str(k)));
  } else if (py::isinstance<py::list>(o) || py::isinstance<py::tuple>(o)) {
    size_t i = 0;
    for (const py::handle v : o) CheckFinite(v, where + "[" + std::to_string(i++) + "]");
  }
}

nlohmann::json FromPython(const py::object& o, const std::string& what) {
  CheckFinite(o, what);
  const std::string text = py::str(py::module_::import("json").attr("dumps")(o));
  return nlohmann::json::parse(text);
}

// A height x width x channels float32 array holding a copy of the image.
py::array_t<float> ToArray(const Image& image) {
  py::array_t<float> a({image.height, image.width, image.channels});
  std::copy(image.data.begin(), image.data.end(), a.mutable_data());
  return a;
}

// Progress lines to a Python callable (or nowhere). The library calls it from the solving
// thread with the GIL released, so the call takes the GIL back.
// The library's log lines to `callback` (None: none), and between them Ctrl-C: a pending
// signal (KeyboardInterrupt) stops the work at its next line, which leaves nothing written
// (a solve writes its scene last, all at once).
Log PythonLog(const py::object& callback) {
  return [callback](const std::string& line) {
    py::gil_scoped_acquire gil;
    if (!callback.is_none()) callback(line);
    if (PyErr_CheckSignals() != 0) throw py::error_already_set();
  };
}

// Ctrl-C during a call that runs with the GIL released. Python's own SIGINT handler only marks
// the signal, and the interpreter acts on it when it runs again: after the call. For the call's
// duration a handler of ours requests the call's Cancellation (the library stops within a few
// milliseconds of work), then hands the signal on to Python's, which raises KeyboardInterrupt
// once the call returns. Installed only over Python's handler (SIGINT ignored, or left to the
// default action, stays so) and by one call at a time; the others still stop at their next
// log line (PythonLog).
class InterruptCancels {
 public:
  explicit InterruptCancels(Cancellation* cancel) {
    const PyOS_sighandler_t current = PyOS_getsig(SIGINT);
    if (current == SIG_IGN || current == SIG_DFL || current == SIG_ERR || current == &Handler)
      return;
    Cancellation* none = nullptr;
    if (!target_.compare_exchange_strong(none, cancel)) return;
    python_handler_ = current;
    PyOS_setsig(SIGINT, &Handler);
    installed_ = true;
  }
  ~InterruptCancels() {
    if (!installed_) return;
    PyOS_setsig(SIGINT, python_handler_);
    target_.store(nullptr);
  }
  InterruptCancels(const InterruptCancels&) = delete;
  InterruptCancels& operator=(const InterruptCancels&) = delete;

 private:
  static void Handler(int sig) {
    if (Cancellation* c = target_.load()) c->Request();
    python_handler_(sig);
  }
  static inline std::atomic<Cancellation*> target_{nullptr};
  static inline PyOS_sighandler_t python_handler_ = nullptr;  // set before Handler is installed
  bool installed_ = false;
};

// A path given as str, bytes or os.PathLike (os.fsdecode: bytes in the file system's encoding).
std::filesystem::path PathOf(const py::object& o) {
  return std::filesystem::path(
      py::str(py::module_::import("os").attr("fsdecode")(o)).cast<std::string>());
}

class PySession {
 public:
  explicit PySession(const py::object& path) : session_(Session::Load(PathOf(path))) {}
  const Session& session() const { return session_; }

  std::string Path() const { return session_.dir().string(); }
  int Slots() const {
    int n = 0;
    for (const FrameRecord& f : session_.frames()) n = std::max(n, f.slot + 1);
    return n;
  }
  std::vector<std::string> Brackets() const {
    std::vector<std::string> names;
    for (const FrameRecord& f : session_.frames()) {
      const std::string& name = f.group;
      if (std::find(names.begin(), names.end(), name) == names.end()) names.push_back(name);
    }
    return names;
  }
  py::object Status(bool verify) const {
    StatusOptions options;
    options.verify_contents = verify;
    return ToPython(StatusToJson(ReadSessionStatus(session_.dir(), options)));
  }

 private:
  Session session_;
};

class PyScene {
 public:
  explicit PyScene(const std::filesystem::path& dir, const Log& log = {})
      : scene_(LoadScene(dir, log)) {}

  std::string Path() const { return scene_.dir.string(); }
  std::vector<std::string> Views() const {
    std::vector<std::string> names;
    for (const auto& [name, view] : scene_.scene.views)
      if (view.target == "architecture") names.push_back(name);
    return names;
  }
  std::vector<std::string> SlotTimes() const {
    std::vector<std::string> times;
    for (const SlotModel& s : scene_.scene.slots) times.push_back(s.utc.Iso8601());
    return times;
  }
  std::vector<int> HoldoutSlots() const { return scene_.scene.holdout_slots; }
  py::object Config() const { return ToPython(SolveConfigJson(scene_.config)); }

  // Exactly one of `time` (ISO 8601) and `slot`; the camera is `view` (a bracket name, empty:
  // the first architecture view) or a lens file and a pose file.
  py::array_t<float> Render(const std::optional<std::string>& time, const std::string& view,
                            std::optional<int> slot, const py::object& lens, const py::object& pose,
                            double pbs, const std::vector<int>& predict_without_slots,
                            bool use_held_out, const py::object& log) const {
    RenderRequest request;
    request.slot = slot;
    if (time) request.time = ParseIso8601(*time);
    request.relight.pbs = pbs;
    request.predict_without_slots = predict_without_slots;
    request.use_held_out_lighting = use_held_out;
    if (lens.is_none() != pose.is_none()) throw Error("lens and pose go together");
    if (!lens.is_none()) {
      if (!view.empty()) throw Error("give a view or a lens and a pose, not both");
      request.intrinsics = ReadLensFile(PathOf(lens).string()).intrinsics;
      request.pose = ReadPoseFile(PathOf(pose).string());
    } else {
      const SceneView& v = FindView(scene_, view);
      request.intrinsics = v.intrinsics;
      request.pose = v.pose;
    }
    CheckRenderRequest(scene_, request);
    const Log say = PythonLog(log);
    Image image;
    {
      py::gil_scoped_release release;
      image = RenderSceneView(scene_, request, say).rgb;
    }
    return ToArray(image);
  }

  py::object Validate(const PySession& session, int slot, const std::vector<std::string>& exclude,
                      int erode_px, bool predicted, const py::object& log) const {
    ValidateOptions options;
    options.exclude_blocks = exclude;
    options.erode_px = erode_px;
    options.predicted = predicted;
    options.Validate();
    const Log say = PythonLog(log);
    Validation v;
    {
      py::gil_scoped_release release;
      v = ValidateSlot(scene_, session.session(), slot, options, say);
    }
    return ToPython(ValidationToJson(v));
  }

 private:
  LoadedScene scene_;
};

// rouen.solve: the same call `rouen solve` makes (SolveSessionFolder).
PyScene Solve(const py::object& session, const py::object& out,
              const std::vector<int>& holdout_slots, bool quick, const py::object& config,
              const py::object& work, bool force, const py::object& log, Cancellation* cancel,
              const py::object& progress) {
  SolveFolderRequest request;
  request.session = py::isinstance<PySession>(session)
                        ? std::filesystem::path(session.cast<const PySession&>().Path())
                        : PathOf(session);
  request.out = PathOf(out);
  if (!work.is_none()) request.work = PathOf(work);
  request.holdout_slots = holdout_slots;
  request.quick = quick;
  if (py::isinstance<py::dict>(config))
    request.config_overrides = FromPython(config, "config");
  else if (!config.is_none())
    request.config_file = PathOf(config).string();
  request.force = force;
  request.log = PythonLog(log);
  if (!progress.is_none()) {
    request.progress = [progress](const SolveEvent& e) {
      py::gil_scoped_acquire gil;
      py::dict figures;
      for (const auto& [name, value] : e.figures) figures[py::str(name)] = value;
      progress(py::dict(py::arg("stage") = e.stage, py::arg("index") = e.index,
                        py::arg("count") = e.count, py::arg("fraction") = e.fraction,
                        py::arg("message") = e.message, py::arg("figures") = figures));
      if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    };
  }
  Cancellation own;  // Ctrl-C's, when the caller gave none
  Cancellation* token = cancel != nullptr ? cancel : &own;
  request.cancel = token;
  try {
    const InterruptCancels interrupts(token);
    py::gil_scoped_release release;
    SolveSessionFolder(request);
  } catch (const Cancelled&) {
    // Ctrl-C (Python's handler marked it) raises KeyboardInterrupt; the caller's request,
    // rouen.Cancelled.
    if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    throw;
  }
  return PyScene(request.out.lexically_normal(), request.log);
}

}  // namespace
}  // namespace rouen

PYBIND11_MODULE(rouen, m) {
  using namespace rouen;
  m.doc() =
      "rouen: recover the lighting and reflectance of a building from photographs (Yu & Malik "
      "1998) and render it at other times of day. The same library as the rouen command.";
  m.attr("__version__") = RouenVersion();
  const auto& error = py::register_exception<Error>(m, "Error", PyExc_RuntimeError);
  // A disk's refusal (a name too long, a file where a folder belongs) is rouen.Error too, as the
  // command reports it ("rouen: error: ..."), not a bare RuntimeError.
  static PyObject* const rouen_error = error.ptr();
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const std::filesystem::filesystem_error& e) {
      PyErr_SetString(rouen_error, e.what());
    }
  });
  // Registered after Error: pybind11 tries the later translator first.
  py::register_exception<Cancelled>(m, "Cancelled", error.ptr());

  py::class_<Cancellation>(
      m, "Cancellation",
      "A token that stops a rouen.solve early: request() it from any thread (a stop button, a "
      "watchdog) and the solve raises rouen.Cancelled within a few milliseconds of work, "
      "leaving no scene. Ctrl-C stops a solve the same way, as KeyboardInterrupt.")
      .def(py::init<>())
      .def("request", &Cancellation::Request, "Ask the work that holds this token to stop")
      .def_property_readonly("requested", &Cancellation::requested);

  py::class_<PySession>(m, "Session", "A session folder (from rouen capture or rouen import).")
      .def(py::init<const py::object&>(), py::arg("path"))
      .def_property_readonly("path", &PySession::Path)
      .def_property_readonly("slots", &PySession::Slots, "Number of times of day captured")
      .def_property_readonly("brackets", &PySession::Brackets,
                             "Bracket names, e.g. slot0/architecture/view0")
      .def("status", &PySession::Status, py::arg("verify") = true,
           "What the session holds and what its solve lacks (as rouen status --json)");

  py::class_<PyScene>(m, "Scene", "A solved scene folder (from rouen solve or rouen.solve).")
      .def(py::init([](const py::object& path) { return PyScene(PathOf(path)); }), py::arg("path"))
      .def_property_readonly("path", &PyScene::Path)
      .def_property_readonly("views", &PyScene::Views, "The architecture views' names")
      .def_property_readonly("slot_times", &PyScene::SlotTimes, "Each slot's UTC time (ISO)")
      .def_property_readonly("holdout_slots", &PyScene::HoldoutSlots)
      .def_property_readonly("config", &PyScene::Config, "The options it was solved with")
      .def(
          "render", &PyScene::Render, py::arg("time") = py::none(), py::arg("view") = "",
          py::kw_only(), py::arg("slot") = py::none(), py::arg("lens") = py::none(),
          py::arg("pose") = py::none(), py::arg("pbs") = 0.0,
          py::arg("predict_without_slots") = std::vector<int>{}, py::arg("use_held_out") = false,
          py::arg("log") = py::none(),
          "Radiance of the building (height x width x 3 float32) at `time` (ISO 8601, lighting "
          "predicted, §5, from the slots not held out unless `use_held_out`) or at captured `slot` "
          "(lighting measured), seen from `view` or from "
          "`lens` and `pose` files, as rouen render writes it.")
      .def("validate", &PyScene::Validate, py::arg("session"), py::arg("slot"),
           py::arg("exclude_blocks") = std::vector<std::string>{}, py::arg("erode_px") = 1,
           py::arg("predicted") = true, py::arg("log") = py::none(),
           "Figures of the slot's photos against renders (as rouen validate --json)");

  m.def("solve", &Solve, py::arg("session"), py::arg("out"),
        py::arg("holdout_slots") = std::vector<int>{}, py::arg("quick") = false,
        py::arg("config") = py::none(), py::arg("work") = py::none(), py::arg("force") = false,
        py::arg("log") = py::none(), py::arg("cancel") = nullptr, py::arg("progress") = py::none(),
        "Calibrate and solve a session into the scene folder `out` (as rouen solve); "
        "`config` is a TOML file or a dict of the options rouen solve --print-config lists. "
        "Does nothing when `out` is up to date. Returns the Scene. A `cancel` token "
        "(rouen.Cancellation) requested from another thread, or Ctrl-C, stops it early "
        "(rouen.Cancelled, KeyboardInterrupt) with no scene written. `progress` is called with "
        "a dict per step of the solve's stages: stage, index, count (the stages), fraction "
        "(0 as the stage starts, 1 when done), message and, when done, its figures.");
  m.def(
      "read_image",
      [](const py::object& path) { return ToArray(ReadImage(PathOf(path).string())); },
      py::arg("path"), "An image file as a height x width x channels float32 array");
}
