#include "capture/rig.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "core/error.h"
#include "core/lens.h"

namespace rouen {
namespace {

const char* kGood = R"(
[rig]
name = "t"
kind = "sim"
[site]
lat_deg = 10.5
lon_deg = 20.25
height_m = 3
[bracket]
step_stops = 1.5
[plan]
date = "2026-08-25"
timezone = "-07:00"
times = ["07:45", "16:00"]
heldout = "16:00"
aureole_exposures_s = [0.001, 0.002]
)";

TEST(RigTest, ParsesSiteBracketAndSlots) {
  RigConfig r = ParseRig(kGood, "good.toml");
  EXPECT_EQ(r.kind, "sim");
  EXPECT_DOUBLE_EQ(r.site.lat_deg, 10.5);
  EXPECT_DOUBLE_EQ(r.site.lon_deg, 20.25);
  EXPECT_DOUBLE_EQ(r.plan.bracket.step_stops, 1.5);
  ASSERT_EQ(r.plan.slots.size(), 2u);
  // 07:45 at -07:00 is 14:45 UTC.
  EXPECT_EQ(r.plan.slots[0].Iso8601(0), "2026-08-25T14:45:00Z");
  EXPECT_EQ(r.heldout_slot, 1);
  ASSERT_EQ(r.plan.aureole_exposures_s.size(), 2u);
}

// `text` with its first `from` replaced by `to`.
std::string Replaced(std::string text, const std::string& from, const std::string& to) {
  const size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return at == std::string::npos ? text : text.replace(at, from.size(), to);
}

void ExpectErrorAt(const std::string& text, const std::string& where) {
  try {
    ParseRig(text, "bad.toml");
    FAIL() << "no error for:\n" << text;
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(where), std::string::npos)
        << "wanted: " << where << "\n got: " << e.what();
  }
}

TEST(RigTest, MalformedRigsNameFileAndLine) {
  ExpectErrorAt("[rig]\nname = \"x\"\nkind = = \"sim\"\n", "bad.toml:3");    // syntax
  ExpectErrorAt("[rig]\nname = \"x\"\nkind = \"webcam9\"\n", "bad.toml:3");  // unknown kind
  ExpectErrorAt(std::string(kGood) + "\n[camera]\ncontrol_latency_frames = \"two\"\n",
                "bad.toml:");  // type
  std::string bad_time = kGood;
  bad_time.replace(bad_time.find("07:45"), 5, "25:99");
  ExpectErrorAt(bad_time, "bad slot time");
  std::string bad_held = kGood;
  bad_held.replace(bad_held.find("heldout = \"16:00\""), 17, "heldout = \"12:00\"");
  ExpectErrorAt(bad_held, "heldout time '12:00'");
  std::string bad_step = kGood;
  bad_step.replace(bad_step.find("1.5"), 3, "9.0");
  ExpectErrorAt(bad_step, "step_stops");
  ExpectErrorAt("[site]\nlat_deg = 1\n", "missing table [rig]");
  // Found by tests/fuzz/rig_fuzz: a zero start exposure passed ParseRig and failed only when
  // the capture validated its plan, naming neither file nor line.
  ExpectErrorAt(std::string(kGood) + "sun_start_exposure_s = 0.000\n",
                "bad.toml:17: [plan] 'sun_start_exposure_s': exposure 0 s is not positive");
  ExpectErrorAt(std::string(kGood) + "start_exposure_s = -0.004\n",
                "bad.toml:17: [plan] 'start_exposure_s': exposure -0.004 s is not positive");
  // Found by tests/fuzz/rig_fuzz: "seed = 1e308" (or -1) was converted to an unsigned integer
  // out of its range, undefined behaviour.
  for (const char* seed : {"1e308", "-1", "2.5"}) {
    std::string bad_seed = kGood;
    bad_seed.replace(bad_seed.find("kind = \"sim\""), 12,
                     "kind = \"sim\"\nseed = " + std::string(seed));
    ExpectErrorAt(bad_seed, "bad.toml:5: [rig] 'seed' must be an integer within 0..");
  }
  std::string big_seed = kGood;
  big_seed.replace(big_seed.find("kind = \"sim\""), 12, "kind = \"sim\"\nseed = 9007199254740993");
  EXPECT_EQ(ParseRig(big_seed, "big.toml").seed, 9007199254740993u);  // not rounded to a double
}

TEST(RigTest, ShippedRigsLoad) {
  for (const char* name : {"sim.toml", "replay.toml"}) {
    std::filesystem::path p = std::filesystem::path(ROUEN_SOURCE_DIR) / "rigs" / name;
    RigConfig r = LoadRig(p);
    EXPECT_FALSE(r.name.empty()) << p;
  }
  RigConfig sim = LoadRig(std::filesystem::path(ROUEN_SOURCE_DIR) / "rigs/sim.toml");
  EXPECT_EQ(sim.plan.slots.size(), 5u);
  EXPECT_GE(sim.heldout_slot, 0);
}

// [solve] is kept as JSON for the pipeline (which knows the solve's keys); TOML that JSON
// cannot hold is an error naming the file.
TEST(RigTest, SolveTableIsKeptForTheSessions) {
  RigConfig r =
      ParseRig(std::string(kGood) + "[solve]\ngrid.block_spacing_m.plaza = 2.5\n", "solve.toml");
  EXPECT_EQ(r.solve_config["grid"]["block_spacing_m"]["plaza"], 2.5);
  EXPECT_TRUE(ParseRig(kGood, "good.toml").solve_config.empty());
  EXPECT_EQ(LoadRig(std::filesystem::path(ROUEN_SOURCE_DIR) / "rigs" / "sim.toml")
                .solve_config["grid"]["block_spacing_m"]["plaza"],
            1.5);
  try {
    ParseTomlAsJson("a = 1\nb = = 2\n", "x.toml");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("x.toml:2"), std::string::npos) << e.what();
  }
  EXPECT_EQ(ParseTomlAsJson("[t]\nk = \"v\"\n", "y.toml")["t"]["k"], "v");
}

TEST(RigTest, MissingFileIsAnError) { EXPECT_THROW(LoadRig("/nonexistent/rig.toml"), Error); }

const char* kField = R"(
[rig]
name = "webcam"
kind = "uvc-webcam"
[site]
lat_deg = 48.86
lon_deg = 2.35
[camera]
id = "c920"
device = "/dev/video2"
width = 1920
height = 1080
pixel_format = "YUYV"
control_latency_frames = 4
lens = "lenses/c920.json"
[lens]
sky = "/abs/fisheye.json"
[gps]
source = "nmea"
device = "/dev/ttyACM0"
baud = 38400
[nd]
sun_density = [4.4, 4.5, 4.9]
[plan]
views = { architecture = 6, landscape = 2 }
[capture]
on_device_lost = "reconnect"
reconnect_timeout_s = 30
)";

TEST(RigTest, FieldRigCarriesDriverGpsNdAndPolicy) {
  RigConfig r = ParseRig(kField, "/rigs/webcam.toml");
  EXPECT_FALSE(r.simulated());
  EXPECT_EQ(r.camera.id, "c920");
  EXPECT_EQ(r.camera.device, "/dev/video2");
  EXPECT_EQ(r.camera.width, 1920);
  EXPECT_EQ(r.camera.control_latency_frames, 4);
  EXPECT_EQ(r.LensPath(Target::kArchitecture), "/rigs/lenses/c920.json");
  EXPECT_EQ(r.LensPath(Target::kSky), "/abs/fisheye.json");
  EXPECT_EQ(r.gps.source, "nmea");
  EXPECT_EQ(r.gps.baud, 38400);
  EXPECT_DOUBLE_EQ(r.sun_nd_density_rgb[2], 4.9);
  EXPECT_NEAR(r.plan.sun_nd_density, (4.4 + 4.5 + 4.9) / 3, 1e-12);
  EXPECT_EQ(r.views.at(Target::kArchitecture), 6);
  EXPECT_EQ(r.views.at(Target::kLandscape), 2);
  EXPECT_EQ(r.on_device_lost, DeviceLostPolicy::kReconnect);
  EXPECT_DOUBLE_EQ(r.reconnect_timeout_s, 30);
  EXPECT_TRUE(r.plan.slots.empty());  // a field rig shoots now
}

TEST(RigTest, MalformedFieldRigsNameTheLine) {
  auto with = [](const std::string& from, const std::string& to) {
    return Replaced(kField, from, to);
  };
  ExpectErrorAt(with("baud = 38400", "baud = -3"), "bad.toml:21");
  ExpectErrorAt(with("source = \"nmea\"", "source = \"glonass\""), "unknown GPS source");
  ExpectErrorAt(with("device = \"/dev/ttyACM0\"\n", ""), "needs 'device'");
  ExpectErrorAt(with("[4.4, 4.5, 4.9]", "[4.4, 4.5]"), "three (R, G, B)");
  ExpectErrorAt(with("[4.4, 4.5, 4.9]", "12"), "within 0..10");
  ExpectErrorAt(with("architecture = 6", "architecture = 0"), "1..64");
  ExpectErrorAt(with("architecture = 6", "roof = 2"), "unknown target");
  ExpectErrorAt(with("\"reconnect\"", "\"pray\""), "on_device_lost");
  ExpectErrorAt(with("width = 1920", "width = 19.5"), "integer");
  ExpectErrorAt(with("[capture]", "[plan2]\ntimes = [\"10:00\"]\n[capture]"),
                "bad.toml:26: unknown table [plan2]");
  ExpectErrorAt(with("baud = 38400", "baud = 38400\nbaudrate = 9600"),
                "bad.toml:22: unknown key 'baudrate' in [gps]");
  ExpectErrorAt(with("views =", "date = \"2026-01-01\"\ntimes = [\"10:00\"]\nviews ="),
                "field rig captures one slot per run");
}

TEST(RigTest, PlanListsSitesAndExposuresAreBounded) {
  auto with = [](const std::string& from, const std::string& to) {
    return Replaced(kGood, from, to);
  };
  // 10000 aureole exposures would capture for hours: refused with the bound, at the key's line.
  std::string many = "[";
  for (int i = 0; i < 10000; ++i) many += (i ? ", " : "") + std::string("0.001");
  many += "]";
  ExpectErrorAt(with("[0.001, 0.002]", many),
                "bad.toml:16: [plan] 'aureole_exposures_s' has 10000 entries; at most 32");
  ExpectErrorAt(with("[0.001, 0.002]", "[0.001, 1e308]"),
                "bad.toml:16: [plan] 'aureole_exposures_s': exposure 1e+308 s is outside "
                "1e-09..86400 s");
  std::string times = "[";
  for (int i = 0; i < 49; ++i) times += (i ? ", " : "") + std::string("\"07:45\"");
  times += "]";
  ExpectErrorAt(with("[\"07:45\", \"16:00\"]", times), "'times' has 49 entries; at most 48");
  ExpectErrorAt(with("heldout = \"16:00\"",
                     "targets = [\"sky\", \"sun\", \"sky\", \"sky\", \"sky\", \"sky\", "
                     "\"sky\"]"),
                "'targets' has 7 entries; at most 6");
  ExpectErrorAt(with("heldout = \"16:00\"", "targets = [\"sky\", \"sky\"]"),
                "'sky' is listed twice");
  // The site: one rule for heights (core/limits.h), latitude and longitude likewise.
  ExpectErrorAt(with("height_m = 3", "height_m = 1e15"),
                "bad.toml:8: [site] 'height_m': height 1e+15 m is outside -500..9000 m");
  ExpectErrorAt(with("lon_deg = 20.25", "lon_deg = 200"),
                "bad.toml:7: [site] 'lon_deg': longitude 200 deg is outside -180..180 deg");
  ExpectErrorAt(with("[bracket]", "[bracket]\nmax_exposure_s = 1e9"),
                "[bracket] 'max_exposure_s': exposure 1e+09 s is outside");
  ExpectErrorAt(with("[rig]\n", "[rig]\nseed = -1\n"), "'seed' must be an integer within 0..");
}

// The shipped gphoto2 rigs: a DSLR over USB (bracket plan, ND for the sun, a fisheye for the
// sky) and a 360-degree camera over PTP/IP for the sky and the landscape (an equirect lens).
TEST(RigTest, Gphoto2RigsCarryTheirCameraAndLenses) {
  const std::filesystem::path rigs = std::filesystem::path(ROUEN_SOURCE_DIR) / "rigs";
  const RigConfig dslr = LoadRig(rigs / "dslr-gphoto2.toml");
  EXPECT_EQ(dslr.kind, "gphoto2");
  EXPECT_FALSE(dslr.simulated());
  EXPECT_EQ(dslr.camera.id, "dslr0");
  EXPECT_TRUE(dslr.camera.gphoto2.port.empty());  // the first camera found
  EXPECT_DOUBLE_EQ(dslr.camera.gphoto2.aperture_f, 8.0);
  EXPECT_FALSE(dslr.camera.gphoto2.delete_on_camera);
  EXPECT_EQ(dslr.camera.gphoto2.max_attempts, 5);
  EXPECT_DOUBLE_EQ(dslr.camera.gphoto2.exif_tolerance_stops, 0.17);
  EXPECT_DOUBLE_EQ(dslr.plan.sun_nd_density, 5.0);
  EXPECT_EQ(dslr.plan.targets.size(), 5u);
  EXPECT_EQ(dslr.views.at(Target::kArchitecture), 4);
  EXPECT_EQ(dslr.on_device_lost, DeviceLostPolicy::kReconnect);
  const LensFile body = ReadLensFile(dslr.LensPath(Target::kArchitecture));
  const LensFile sky = ReadLensFile(dslr.LensPath(Target::kSky));
  EXPECT_EQ(body.intrinsics.projection, Projection::kPinhole);
  EXPECT_EQ(sky.intrinsics.projection, Projection::kFisheye);
  EXPECT_EQ(sky.intrinsics.width, body.intrinsics.width);  // the same body's JPEG size

  const RigConfig pano = LoadRig(rigs / "360-gphoto2.toml");
  EXPECT_EQ(pano.kind, "gphoto2");
  EXPECT_EQ(pano.camera.gphoto2.port, "ptpip:192.168.1.1");
  EXPECT_EQ(pano.camera.gphoto2.model, "PTP/IP Camera");
  EXPECT_EQ(pano.plan.targets, (std::vector<Target>{Target::kSky, Target::kLandscape}));
  EXPECT_DOUBLE_EQ(pano.plan.sun_nd_density, 0.0);
  for (Target t : pano.plan.targets) {
    const LensFile lens = ReadLensFile(pano.LensPath(t));
    EXPECT_EQ(lens.intrinsics.projection, Projection::kEquirect) << TargetName(t);
    EXPECT_EQ(lens.intrinsics.width, 2 * lens.intrinsics.height) << TargetName(t);
  }
}

// gphoto2's [camera] keys belong to gphoto2 rigs, the streaming drivers' to theirs; values out
// of range name the file, the line and the key.
TEST(RigTest, Gphoto2CameraKeysAreCheckedByKind) {
  const std::string gphoto2 =
      "[rig]\nname = \"g\"\nkind = \"gphoto2\"\n[site]\nlat_deg = 1\nlon_deg = 2\n"
      "[camera]\nmodel = \"Canon EOS 5D Mark IV\"\nserial = \"0123\"\n"
      "max_attempts = 3\nbackoff_initial_s = 0.2\n";
  const RigConfig g = ParseRig(gphoto2, "g.toml");
  EXPECT_EQ(g.camera.gphoto2.model, "Canon EOS 5D Mark IV");
  EXPECT_EQ(g.camera.gphoto2.serial, "0123");
  EXPECT_EQ(g.camera.gphoto2.max_attempts, 3);
  EXPECT_DOUBLE_EQ(g.camera.gphoto2.backoff_initial_s, 0.2);
  EXPECT_DOUBLE_EQ(g.camera.gphoto2.capture_timeout_s, 30);  // Gphoto2Options' default
  ExpectErrorAt(Replaced(kField, "device = \"/dev/video2\"", "port = \"usb:001,004\""),
                "bad.toml:10: [camera] 'port' is for gphoto2 rigs only (this rig's kind is "
                "'uvc-webcam')");
  ExpectErrorAt(gphoto2 + "pixel_format = \"YUYV\"\n",
                "bad.toml:12: [camera] 'pixel_format' is not used by gphoto2 rigs");
  ExpectErrorAt(gphoto2 + "device = \"/dev/video0\"\n", "name the camera with 'model'");
  ExpectErrorAt(Replaced(gphoto2, "max_attempts = 3", "max_attempts = 0"),
                "bad.toml:10: [camera] 'max_attempts' must be an integer within 1..100");
  ExpectErrorAt(gphoto2 + "backoff_max_s = 0.1\n",
                "bad.toml:12: [camera] 'backoff_max_s' must be at least backoff_initial_s");
  ExpectErrorAt(gphoto2 + "aperture_f = 300\n", "bad.toml:12: [camera] 'aperture_f'");
  ExpectErrorAt(gphoto2 + "delete_on_camera = \"no\"\n",
                "'delete_on_camera' must be true or false");
  ExpectErrorAt(gphoto2 + "exif_tolerance_stops = 0\n",
                "'exif_tolerance_stops' must be within (0, 10]");
}

TEST(RigTest, EveryShippedRigParses) {
  int n = 0;
  for (const auto& e :
       std::filesystem::directory_iterator(std::filesystem::path(ROUEN_SOURCE_DIR) / "rigs")) {
    if (e.path().extension() != ".toml") continue;
    RigConfig r = LoadRig(e.path());
    EXPECT_FALSE(r.name.empty()) << e.path();
    ++n;
  }
  EXPECT_GE(n, 8);  // sim, replay, uvc-webcam, rpi-libcamera, gige-aravis, aravis-fake, and
                    // the gphoto2 DSLR and 360-degree rigs
}

}  // namespace
}  // namespace rouen
