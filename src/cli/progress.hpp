// A progress bar on stderr for long jobs: shown only when stderr is a terminal and the job has
// run for more than half a second; cleared when done.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <thread>

namespace odomcov::cli {

class ProgressBar {
 public:
  /// `done` is polled every 200 ms; `total` is the amount of work; `unit` labels it.
  ProgressBar(std::function<std::int64_t()> done, std::int64_t total, std::string unit);
  /// For work whose amount is learnt as it goes (polled like `done`); while it is <= 0 the bar
  /// shows a counter and the elapsed time instead.
  ProgressBar(std::function<std::int64_t()> done, std::function<std::int64_t()> total,
              std::string unit);
  /// The same with a label that changes as the work goes ("fits, round 3"), polled like `done`.
  ProgressBar(std::function<std::int64_t()> done, std::function<std::int64_t()> total,
              std::function<std::string()> unit);
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  /// Stops the updater thread and clears the line (also done by the destructor).
  void finish();

  static bool enabled();  // stderr is a terminal

 private:
  void loop();
  void draw(std::int64_t done, double elapsed_s);

  std::function<std::int64_t()> done_;
  std::function<std::int64_t()> total_;
  std::function<std::string()> unit_;
  std::atomic<bool> stop_{false};
  bool drawn_ = false;
  std::chrono::steady_clock::time_point start_;
  std::thread thread_;
};

}  // namespace odomcov::cli
