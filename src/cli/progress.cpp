#include "progress.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace odomcov::cli {
namespace {

constexpr auto kPollInterval = std::chrono::milliseconds(200);
constexpr double kShowAfterSeconds = 0.5;
constexpr int kBarWidth = 30;

std::string duration_text(double seconds) {
  char buf[32];
  if (seconds < 60) {
    std::snprintf(buf, sizeof buf, "%.0f s", seconds);
  } else if (seconds < 3600) {
    const double minutes = std::floor(seconds / 60);
    std::snprintf(buf, sizeof buf, "%.0f min %02.0f s", minutes, std::floor(seconds - 60 * minutes));
  } else {
    std::snprintf(buf, sizeof buf, "%.1f h", seconds / 3600);
  }
  return buf;
}

}  // namespace

bool ProgressBar::enabled() { return ::isatty(STDERR_FILENO) == 1; }

ProgressBar::ProgressBar(std::function<std::int64_t()> done, std::int64_t total, std::string unit)
    : done_(std::move(done)), total_([total] { return total; }), unit_([unit] { return unit; }),
      start_(std::chrono::steady_clock::now()) {
  if (enabled() && total > 0) thread_ = std::thread([this] { loop(); });
}

ProgressBar::ProgressBar(std::function<std::int64_t()> done, std::function<std::int64_t()> total,
                         std::string unit)
    : ProgressBar(std::move(done), std::move(total), std::function<std::string()>([unit] { return unit; })) {}

ProgressBar::ProgressBar(std::function<std::int64_t()> done, std::function<std::int64_t()> total,
                         std::function<std::string()> unit)
    : done_(std::move(done)), total_(std::move(total)), unit_(std::move(unit)),
      start_(std::chrono::steady_clock::now()) {
  if (enabled()) thread_ = std::thread([this] { loop(); });
}

ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::finish() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  if (drawn_) {
    std::fprintf(stderr, "\r\033[K");
    std::fflush(stderr);
    drawn_ = false;
  }
}

void ProgressBar::loop() {
  while (!stop_) {
    std::this_thread::sleep_for(kPollInterval);
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    if (!stop_ && elapsed > kShowAfterSeconds) draw(done_(), elapsed);
  }
}

void ProgressBar::draw(std::int64_t done, double elapsed_s) {
  const std::int64_t total = total_();
  if (total <= 0) {
    std::fprintf(stderr, "\r\033[K%lld %s  %s", static_cast<long long>(done), unit_().c_str(),
                 duration_text(elapsed_s).c_str());
    std::fflush(stderr);
    drawn_ = true;
    return;
  }
  const double fraction = std::min(1.0, static_cast<double>(done) / static_cast<double>(total));
  const int filled = static_cast<int>(fraction * kBarWidth);
  std::string bar(static_cast<std::size_t>(filled), '#');
  bar.resize(kBarWidth, '.');
  const std::string eta =
      fraction > 0 ? duration_text(elapsed_s * (1.0 - fraction) / fraction) : std::string("?");
  std::fprintf(stderr, "\r\033[K[%s] %3.0f%%  %lld/%lld %s  ETA %s", bar.c_str(), 100 * fraction,
               static_cast<long long>(done), static_cast<long long>(total), unit_().c_str(),
               eta.c_str());
  std::fflush(stderr);
  drawn_ = true;
}

}  // namespace odomcov::cli
