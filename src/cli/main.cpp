// odomcov: closed-form odometry covariance, validated by Monte-Carlo and against measurements.
#include <CLI/CLI.hpp>

#include <iostream>

#include "commands.hpp"
#include "odomcov/base/error.hpp"
#include "output.hpp"

int main(int argc, char** argv) {
  using namespace odomcov::cli;
  CLI::App app{"odomcov: how far to trust wheel odometry, and the proof", "odomcov"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "odomcov 0.1.0");
  int exit_code = kExitOk;
  setup_theory(app, exit_code);
  setup_run(app, exit_code);
  setup_sweep(app, exit_code);
  setup_synth(app, exit_code);
  setup_compare(app, exit_code);
  setup_fit(app, exit_code);
  setup_umbmark(app, exit_code);
  setup_diagnose(app, exit_code);
  setup_calibrate(app, exit_code);
  setup_import(app, exit_code);
  setup_predict(app, exit_code);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "odomcov: " << odomcov::one_line(e.what()) << " (see odomcov --help)\n";
    return kExitBadInput;
  } catch (const odomcov::InputError& e) {
    std::cerr << "odomcov: " << e.what() << "\n";
    return kExitBadInput;
  } catch (const UsageError& e) {
    std::cerr << "odomcov: " << odomcov::one_line(e.what()) << "\n";
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::cerr << "odomcov: internal error: " << odomcov::one_line(e.what()) << "\n";
    return 3;
  }
  return exit_code;
}
