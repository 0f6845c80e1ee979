// The mujoco program as a user runs it, on any MJCF scene (examples/models/, tests/models/):
// --dump-gradients against finite differences, training, --check-derivatives, and the models,
// targets, flags and checkpoints it refuses.
#include <sys/stat.h>

#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "programs/program_runner.hpp"
#include "sbptt/nn/parameters_io.hpp"
#include "support/address_sanitizer.hpp"

namespace fs = std::filesystem;
using sbptt::testing::file_text;
using sbptt::testing::gradient_column;
using sbptt::testing::printed_loss;
using sbptt::testing::Result;
using sbptt::testing::run;
using sbptt::testing::scratch;

namespace {

std::string model_file(const std::string& relative) {
  return std::string(SBPTT_SOURCE_DIR) + "/" + relative;
}

/// A copy of the model at `relative` with `from` replaced by `to`, in the scratch folder.
fs::path edited_model(const std::string& relative, const std::string& from, const std::string& to,
                      const std::string& name) {
  std::string text = file_text(model_file(relative));
  const auto at = text.find(from);
  REQUIRE(at != std::string::npos);
  text.replace(at, from.size(), to);
  const fs::path file = scratch(name);
  std::ofstream(file) << text;
  return file;
}

const std::string double_pendulum =
    "--model " + model_file("examples/models/double_pendulum.xml") + " --target 3.14159,0 ";

}  // namespace

TEST_CASE("mujoco --dump-gradients: R equals central differences of the printed batch loss",
          "[programs][mujoco]") {
  // End to end through MuJoCo's finite-difference Jacobians and the hinge loss 1 − cos.
  const fs::path params = scratch("mujoco.params"), dump = scratch("mujoco_dump.csv");
  const std::string base = double_pendulum + "--samples 4 --steps 30 --spread 1 ";
  REQUIRE(run("mujoco", base + "--epochs 3 --save-params " + params.string()).status == 0);
  const Result at = run("mujoco", base + "--init-params " + params.string() +
                                      " --dump-gradients " + dump.string());
  INFO(at.output);
  REQUIRE(at.status == 0);
  const std::vector<double> regular = gradient_column(dump, 1);
  REQUIRE(regular.size() == 10802);  // 4 → 100 → 100 → 2
  const auto theta =
      sbptt::load_parameters<double>(params, static_cast<sbptt::Index>(regular.size()));
  const double h = 1e-6;
  // A first-layer weight, a last-layer weight and the last bias (the elbow torque's).
  for (sbptt::Index p : {sbptt::Index{7}, sbptt::Index{10700}, sbptt::Index{10801}}) {
    double losses[2];
    for (int side = 0; side < 2; ++side) {
      auto shifted = theta;
      shifted(p) += side == 0 ? h : -h;
      const fs::path file = scratch("mujoco_shifted.params");
      sbptt::save_parameters(file, shifted);
      const Result r = run("mujoco", base + "--init-params " + file.string() +
                                         " --dump-gradients " + scratch("unused.csv").string());
      REQUIRE(r.status == 0);
      losses[side] = printed_loss(r.output);
    }
    INFO("parameter " << p);
    CHECK(regular[static_cast<std::size_t>(p)] ==
          Approx((losses[0] - losses[1]) / (2 * h)).epsilon(1e-5).margin(1e-9));
  }
}

TEST_CASE("mujoco trains the double pendulum up, and --threads 2 changes no bit",
          "[programs][mujoco]") {
  const std::string arguments =
      double_pendulum + "--method C --epochs 30 --samples 16 --steps 100 --lr 0.01";
  const fs::path one = scratch("mujoco_t1.params"), two = scratch("mujoco_t2.params");
  const fs::path log = scratch("mujoco.csv");
  const Result r1 = run("mujoco", arguments + " --csv " + log.string() + " --save-params " +
                                      one.string());
  const Result r2 = run("mujoco", arguments + " --threads 2 --save-params " + two.string());
  INFO(r1.output << r2.output);
  REQUIRE(r1.status == 0);
  REQUIRE(r2.status == 0);
  CHECK(file_text(one) == file_text(two));
  // Hanging (1 − cos π = 2 on the shoulder) to below a tenth of it (measured: 1.9997 to 0.013).
  const auto initial = r1.output.find("initial test loss ");
  REQUIRE(initial != std::string::npos);
  CHECK(std::stod(r1.output.substr(initial + 18)) > 1.9);
  const auto at = r1.output.find("final test loss ");
  REQUIRE(at != std::string::npos);
  CHECK(std::stod(r1.output.substr(at + 16)) < 0.2);
  std::ifstream in(log);
  std::string header;
  std::getline(in, header);
  CHECK(header == "epoch,batch_loss,train_loss,test_loss,update_norm2,cos_m_r,agree_fraction,seconds");
}

TEST_CASE("mujoco --check-derivatives prints mjd_transitionFD's agreement with sbptt's own",
          "[programs][mujoco]") {
  const Result r = run("mujoco", "--model " + model_file("tests/models/cartpole_physical_2.xml") +
                                     " --check-derivatives");
  INFO(r.output);
  REQUIRE(r.status == 0);
  const auto at = r.output.find("worst relative error at 5 states: A ");
  REQUIRE(at != std::string::npos);
  std::stringstream fields(r.output.substr(at + 36));
  double a = 1, b = 1, vjp = 1;
  std::string skip;
  fields >> a >> skip >> skip >> b >> skip >> skip >> vjp;
  CHECK(a < 1e-6);
  CHECK(b < 1e-6);
  CHECK(vjp < 1e-6);  // against central differences of the step, like A and B
  CHECK(r.output.find("below the tolerance 1e-06 of a smooth model in double: the derivatives "
                      "agree") != std::string::npos);
}

TEST_CASE("mujoco --check-derivatives fails where the derivatives disagree, naming the worst",
          "[programs][mujoco]") {
  // A ball at rest on the floor exactly where contact begins (--spread 0): each difference in
  // its height straddles the contact's onset, so MuJoCo's differences and sbptt's (another
  // step) give different slopes of the same kink. A verdict of 0 would send a user on to train
  // on noise.
  const fs::path touching = scratch("touching_ball.xml");
  std::ofstream(touching) << R"(<mujoco><option timestep="0.01"/><worldbody>
    <geom type="plane" size="1 1 0.1"/>
    <body pos="0 0 0.1"><joint name="lift" type="slide" axis="0 0 1"/>
      <geom type="sphere" size="0.1" mass="1"/></body>
    </worldbody><actuator><motor joint="lift" gear="1"/></actuator></mujoco>)";
  const Result r =
      run("mujoco", "--model " + touching.string() + " --check-derivatives --spread 0");
  INFO(r.output);
  CHECK(r.status == 3);
  CHECK(r.output.find("above the tolerance 1e-06 of a smooth model in double (A ") !=
        std::string::npos);
  CHECK(r.output.find("expected errors below 1e-06") != std::string::npos);
  // The entry: the height's column of A, whose kink MuJoCo's differences and sbptt's straddle.
  CHECK(r.output.find("The worst, at state ") != std::string::npos);
  CHECK(r.output.find(" at A(") != std::string::npos);
  CHECK(r.output.find(", 0): ") != std::string::npos);
  CHECK(r.output.find(" by jacobians, ") != std::string::npos);
}

TEST_CASE("mujoco refuses a model or target it cannot use, naming it", "[programs][mujoco]") {
  const fs::path broken = scratch("broken.xml"), passive = scratch("passive.xml"),
                 ball = scratch("ball.xml");
  std::ofstream(broken) << "<mujoco><worldbody><body>";
  // Read, but not a model: exit 2 as a bad --model (docs/programs.md), MuJoCo's reason quoted.
  const fs::path empty = scratch("empty.xml"), text = scratch("text.xml"),
                 includes_nothing = scratch("includes_nothing.xml");
  std::ofstream(empty) << "";
  std::ofstream(text) << "not xml at all\n";
  std::ofstream(includes_nothing) << "<mujoco><include file='no_such_part.xml'/></mujoco>";
  std::ofstream(passive) << "<mujoco><worldbody><body><joint type='hinge'/><geom size='0.1'/>"
                            "</body></worldbody></mujoco>";
  std::ofstream(ball) << "<mujoco><worldbody><body><joint name='j' type='ball'/><geom "
                         "size='0.1'/></body></worldbody><actuator><general joint='j' "
                         "gear='1 0 0 0 0 0'/></actuator></mujoco>";
  // No joint: a site motor drives nothing. Without an activation the state is empty; with one
  // (a filter) it is the activation alone, and no position is there for --target to aim.
  const fs::path jointless = scratch("jointless.xml"), activation = scratch("activation.xml");
  const std::string site_body =
      "<mujoco><worldbody><body><geom size='0.1'/><site name='s'/></body></worldbody>";
  std::ofstream(jointless) << site_body
                           << "<actuator><motor site='s' gear='1 0 0 0 0 0'/></actuator></mujoco>";
  std::ofstream(activation) << site_body
                            << "<actuator><general site='s' dyntype='filter' dynprm='1' "
                               "gear='1 0 0 0 0 0'/></actuator></mujoco>";
  struct Case {
    std::string arguments, expected;
  };
  const std::string acrobot = "--model " + model_file("examples/models/acrobot.xml");
  for (const Case& c :
       {Case{"--model " + broken.string() + " --target 0", "XML_ERROR_MISMATCHED_ELEMENT"},
        Case{"--model " + empty.string() + " --target 0", "XML_ERROR_EMPTY_DOCUMENT"},
        Case{"--model " + text.string() + " --target 0", "XML_ERROR_PARSING_TEXT"},
        Case{"--model " + includes_nothing.string() + " --target 0", "no_such_part.xml"},
        Case{"--model " + passive.string() + " --target 0", "no actuator (nu = 0)"},
        Case{"--model " + ball.string() + " --target 0,0,0,0", "quaternion"},
        Case{"--model " + jointless.string() + " --target 0",
             "no joint (nv = 0) and no actuator activation (na = 0), so its state is empty"},
        Case{"--model " + jointless.string() + " --check-derivatives", "its state is empty"},
        Case{"--model " + activation.string(),
             "has no position coordinate (nq = 0), so --target has nothing to aim at"},
        Case{acrobot + " --target 1,2,3",
             "--target '1,2,3' has 3 value(s); expected nq = 2, one per position coordinate"},
        Case{acrobot + " --target 1,2,3", "shoulder (hinge), elbow (hinge)"},
        Case{acrobot, "--target is required: 2 comma-separated positions"},
        // The message quoted the item alone ("--target '' is not a number"), not the value.
        Case{acrobot + " --target 1,x", "--target '1,x': item 2, 'x', is not a number in "
                                        "[-1000000, 1000000]; expected comma-separated numbers"},
        Case{acrobot + " --target 1,,2", "--target '1,,2': item 2, '', is not a number"},
        Case{acrobot + " --target 1,2 --spread -1", "--spread -1 is out of range"},
        Case{"--target 1", "--model is required"},
        Case{acrobot + " --target 1,2 --poles 2", "unknown flag '--poles'"}}) {
    const Result r = run("mujoco", c.arguments);
    INFO(c.arguments << "\n" << r.output);
    CHECK(r.status == 2);
    CHECK(r.output.find(c.expected) != std::string::npos);
  }
}

TEST_CASE("mujoco says why it cannot read --model, and never writes over it",
          "[programs][mujoco]") {
  const fs::path folder = scratch("model_folder");
  fs::create_directories(folder);
  for (const auto& [model, reason] :
       {std::pair{std::string("/nonexistent/scene.xml"),
                  std::string("--model: load_mujoco_model: cannot open '/nonexistent/scene.xml' "
                              "for reading (No such file or directory)")},
        std::pair{folder.string(), "'" + folder.string() + "' is a directory; expected an MJCF"}}) {
    const Result r = run("mujoco", "--model " + model + " --target 0");
    INFO(r.output);
    CHECK(r.status == 1);
    CHECK(r.output.find(reason) != std::string::npos);
  }
  const std::string original = file_text(model_file("examples/models/double_pendulum.xml"));
  const fs::path copy = scratch("overwritten.xml");
  std::ofstream(copy) << original;
  for (const std::string flag : {"--save-params", "--csv", "--dump-gradients", "--checkpoint"}) {
    const std::string epochs = flag == "--dump-gradients" ? "" : "--epochs 1 ";
    const Result r = run("mujoco", "--model " + copy.string() + " --target 3.14159,0 --samples 4 "
                                   "--steps 10 " + epochs + flag + " " + copy.string());
    INFO(flag << "\n" << r.output);
    CHECK(r.status == 1);
    CHECK(r.output.find("--model '" + copy.string() + "' and " + flag + " '" + copy.string() +
                        "' are the same file") != std::string::npos);
    CHECK(file_text(copy) == original);
  }
}

TEST_CASE("mujoco refuses a --model that is a pipe, before waiting on it", "[programs][mujoco]") {
  // MuJoCo opens the model by its name and reads it as a file: a pipe's model was an "XML
  // read error", exit 2, and a named pipe without a writer hung the program for ever.
  const fs::path fifo = scratch("model_pipe.xml");
  fs::remove(fifo);
  REQUIRE(::mkfifo(fifo.c_str(), 0666) == 0);
  const std::string model = model_file("examples/models/double_pendulum.xml");
  for (const auto& [prefix, path] :
       {std::pair{std::string("cat " + model + " | "), std::string("/dev/stdin")},
        std::pair{std::string("timeout 20 "), fifo.string()}}) {
    const Result r = run("mujoco", "--model " + path + " --target 0", prefix);
    INFO(prefix << path << "\n" << r.output);
    CHECK(r.status == 1);
    CHECK(r.output.find("--model: load_mujoco_model: '" + path + "' is not a regular file (a " +
                        "pipe or a device); expected an MJCF or URDF file") != std::string::npos);
  }
  CHECK(fs::is_fifo(fifo));
}

TEST_CASE("mujoco: a model too large for memory is an error (exit 1), not a bad flag",
          "[programs][mujoco]") {
  // A stack of 10^9 numbers (8 GB) under a 2 GB address-space limit: MuJoCo "Could not
  // allocate memory" was reported as a model that does not load, exit 2 (a bad flag). Under
  // ASan the program cannot start in 2 GB of address space (its shadow memory).
  if (sbptt::testing::address_sanitizer) return;
  const fs::path model = edited_model("examples/models/double_pendulum.xml",
                                      "<mujoco model=\"double_pendulum\">",
                                      "<mujoco model=\"double_pendulum\"><size nstack=\"1000000000\"/>",
                                      "huge_stack.xml");
  const Result r = run("mujoco", "--model " + model.string() + " --target 0,0 --epochs 1",
                       "ulimit -v 2000000; ");
  INFO(r.output);
  CHECK(r.status == 1);
  CHECK(r.output.find("--model: load_mujoco_model: '" + model.string() + "' needs more memory "
                      "than this process may use (MuJoCo: Could not allocate memory)") !=
        std::string::npos);
}

TEST_CASE("mujoco holds the model's own time step to --dt's range", "[programs][mujoco]") {
  const fs::path tiny = edited_model("examples/models/acrobot.xml", "timestep=\"0.01\"",
                                     "timestep=\"1e-300\"", "acrobot_tiny_step.xml");
  const std::string model = "--model " + tiny.string();
  const Result r = run("mujoco", model + " --target 1,2 --epochs 1 --samples 2");
  INFO(r.output);
  CHECK(r.status == 2);
  CHECK(r.output.find("its opt.timestep 1e-300 is out of range; expected a number in [1e-12, "
                      "1000000]") != std::string::npos);
  // With two of --steps, --dt and --T the model's step is not used.
  const Result given =
      run("mujoco", model + " --target 1,2 --epochs 1 --samples 2 --dt 0.01 --steps 10");
  INFO(given.output);
  CHECK(given.status == 0);
}

TEST_CASE("mujoco --check-derivatives fails on derivatives that are not finite",
          "[programs][mujoco]") {
  const fs::path file = edited_model("examples/models/double_pendulum.xml", "damping=\"0.05\"",
                                     "damping=\"1e308\"", "double_pendulum_huge_damping.xml");
  const Result r = run("mujoco", "--model " + file.string() + " --check-derivatives");
  INFO(r.output);
  CHECK(r.status == 3);
  CHECK(r.output.find("an error is not finite: the step or its derivatives are NaN or too large") != std::string::npos);
  CHECK(r.output.find("The worst, at state ") != std::string::npos);
}

TEST_CASE("mujoco: a checkpoint of another --target, --spread or model file is refused, "
          "naming it", "[programs][mujoco]") {
  const std::string original = file_text(model_file("examples/models/double_pendulum.xml"));
  const fs::path moved = scratch("checkpoint_moved.xml"), damped = scratch("checkpoint_damped.xml");
  std::ofstream(moved) << original;
  std::string more_damping = original;
  more_damping.replace(more_damping.find("damping=\"0.05\""), 14, "damping=\"0.07\"");
  std::ofstream(damped) << more_damping;
  const fs::path checkpoint = scratch("mujoco.checkpoint");
  fs::remove(checkpoint);
  const std::string common = "--samples 8 --steps 20 --checkpoint " + checkpoint.string() + " ";
  REQUIRE(run("mujoco", double_pendulum + common + "--epochs 2").status == 0);
  const Result target = run("mujoco", "--model " + model_file("examples/models/double_pendulum.xml") +
                                          " --target 0,0 " + common + "--epochs 4");
  INFO(target.output);
  CHECK(target.status == 2);
  CHECK(target.output.find("was made with --target = 3.14159,0; this run has --target = 0,0") !=
        std::string::npos);
  // The initial states' spread is named as the flag, not as a changed train set.
  const Result spread = run("mujoco", double_pendulum + common + "--spread 0.2 --epochs 4");
  INFO(spread.output);
  CHECK(spread.status == 2);
  CHECK(spread.output.find("was made with --spread = 0.1; this run has --spread = 0.2") !=
        std::string::npos);
  const Result model = run("mujoco", "--model " + damped.string() + " --target 3.14159,0 " +
                                         common + "--epochs 4");
  INFO(model.output);
  CHECK(model.status == 2);
  CHECK(model.output.find("was made with --model = ") != std::string::npos);
  CHECK(model.output.find("epoch 1 ") == std::string::npos);
  // The file's content is the model, not its path nor how the target's numbers are spelled.
  const Result same = run("mujoco", "--model " + moved.string() + " --target 3.14159,0.0 " +
                                        common + "--epochs 3");
  INFO(same.output);
  CHECK(same.status == 0);
  CHECK(same.output.find("resuming after epoch 2") != std::string::npos);
}

TEST_CASE("mujoco --check-derivatives refuses the flags it does not use, before any work",
          "[programs][mujoco]") {
  const fs::path file = scratch("check_derivatives_output");
  fs::remove_all(file);
  const std::string check =
      "--model " + model_file("examples/models/acrobot.xml") + " --check-derivatives ";
  for (const std::string& flag : std::vector<std::string>
       {"--epochs 5", "--csv " + file.string(), "--save-params " + file.string(),
        "--checkpoint " + file.string(), "--dump-gradients " + file.string(),
        "--init-params " + file.string(), "--target 1", "--target 1,2", "--samples 4",
        "--threads 2"}) {
    const Result r = run("mujoco", check + flag);
    const std::string name = flag.substr(0, flag.find(' '));
    INFO(flag << "\n" << r.output);
    CHECK(r.status == 2);
    CHECK(r.output.find("so " + name + " would have no effect; expected --check-derivatives "
                        "without " + name) != std::string::npos);
    CHECK(r.output.find("worst relative error") == std::string::npos);
    CHECK_FALSE(fs::exists(file));
  }
}

TEST_CASE("mujoco refuses a model with a non-finite number before any work, naming the field",
          "[programs][mujoco]") {
  const fs::path file = edited_model("examples/models/acrobot.xml", "gravity=\"0 0 -9.81\"",
                                     "gravity=\"0 0 nan\"", "acrobot_nan_gravity.xml");
  for (const char* mode : {" --target 1,2", " --check-derivatives"}) {
    // MuJoCo's own warning reaches stderr, not stdout nor a MUJOCO_LOG.TXT beside the caller.
    fs::remove("MUJOCO_LOG.TXT");
    const Result quiet = run("mujoco", "--model " + file.string() + mode, "", "2>/dev/null");
    CHECK(quiet.output.empty());
    CHECK_FALSE(fs::exists("MUJOCO_LOG.TXT"));
    const Result r = run("mujoco", "--model " + file.string() + mode);
    INFO(r.output);
    CHECK(r.status == 2);
    CHECK(r.output.find("MuJoCo warns: XML contains a 'NaN'") != std::string::npos);
    CHECK(r.output.find("--model '" + file.string() + "': MujocoSimulator: the model's "
                        "opt.gravity[2] is nan") != std::string::npos);
    CHECK(r.output.find("initial test loss") == std::string::npos);
    CHECK(r.output.find("worst relative error") == std::string::npos);
  }
}

TEST_CASE("mujoco says why MuJoCo refused a step, in MuJoCo's words", "[programs][mujoco]") {
  // Room for one contact and two spheres resting in the plane (--spread 0): every sample's
  // first step overflows it, and the steps from its NaN state are no refusals of MuJoCo's.
  const fs::path file = scratch("contact_full.xml");
  std::ofstream(file)
      << "<mujoco><size nconmax='1'/><worldbody><geom type='plane' size='5 5 .1'/>"
         "<body pos='0 0 0.05'><joint name='a' type='slide' axis='0 0 1'/><geom size='0.1'/>"
         "</body><body pos='1 0 0.05'><joint name='b' type='slide' axis='0 0 1'/><geom "
         "size='0.1'/></body></worldbody><actuator><motor joint='a'/></actuator></mujoco>";
  const std::string why = "its contact buffer is full (increase nconmax above 1)";
  const std::string scene =
      "--model " + file.string() + " --target 0,0 --spread 0 --steps 5 --samples 4 ";
  const Result trained = run("mujoco", scene + "--epochs 2 --batch 2");
  INFO(trained.output);
  CHECK(trained.status == 3);
  CHECK(trained.output.find("in the test set, step 1, sample 0; MuJoCo refused 4 calls (steps "
                            "or their derivatives); the first: " + why) != std::string::npos);
  // C's batch of 2: each sample's first step, and its derivatives in each of the two sweeps.
  CHECK(trained.output.find("in epoch 1, batch 0, step 1, sample 0; MuJoCo refused 6 calls "
                            "(steps or their derivatives); the first: " + why + "\n") !=
        std::string::npos);
  const Result dumped = run("mujoco", scene + "--dump-gradients " + scratch("g.csv").string());
  INFO(dumped.output);
  CHECK(dumped.status == 3);
  CHECK(dumped.output.find("in the forward pass, step 1, sample 0; MuJoCo refused 4 calls (steps "
                           "or their derivatives); the first: " + why +
                           "; no gradients written") != std::string::npos);
  const Result checked =
      run("mujoco", "--model " + file.string() + " --spread 0 --check-derivatives");
  INFO(checked.output);
  CHECK(checked.status == 3);
  CHECK(checked.output.find("at one of the 5 states: MuJoCo refused ") != std::string::npos);
  CHECK(checked.output.find(" calls (steps or their derivatives); the first: " + why) !=
        std::string::npos);
}
