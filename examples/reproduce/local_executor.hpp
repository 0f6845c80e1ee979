// reproduce: the local executor, a pool of --jobs child processes that runs the plan resumably.
#pragma once

#include <fcntl.h>
#include <sys/file.h>
#include <sys/ioctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include <sbptt/core/atomic_file.hpp>
#include <sbptt/train/training_log.hpp>

#include "durable_files.hpp"
#include "finished_run.hpp"
#include "locks.hpp"
#include "options.hpp"
#include "processes.hpp"
#include "run_files.hpp"
#include "summary.hpp"

namespace reproduce {

class Sweep {
public:
  Sweep(const Options& options, std::vector<Run> plan, fs::path bin_dir)
      : options_(options), plan_(std::move(plan)), bin_dir_(std::move(bin_dir)),
        out_(options.out), runs_(out_ / "runs") {}

  /// Returns the exit code of the runner.
  int execute() {
    fs::create_directories(runs_);
    discard_partial_runs();
    forget_damaged();
    write_summary();
    std::vector<const Run*> todo;
    for (const Run& run : plan_)
      if (!is_finished(finished_, run)) todo.push_back(&run);
    double estimate = 0;
    for (const Run* run : todo) estimate += finished_.expected_seconds(*run);
    std::printf("reproduce: profile %s, %s planned (%zu finished, %zu to do), --jobs %ld, "
                "--threads %ld, estimated %s of compute, about %s wall time\n",
                options_.profile.c_str(), count_of(plan_.size(), "run").c_str(),
                plan_.size() - todo.size(), todo.size(),
                options_.jobs, options_.threads, format_duration(estimate).c_str(),
                format_duration(estimate / static_cast<double>(std::min<std::size_t>(
                                               static_cast<std::size_t>(options_.jobs),
                                               std::max<std::size_t>(todo.size(), 1))))
                    .c_str());
    std::printf("reproduce: output in %s (runs/, summary.csv, plots/)\n", out_.c_str());
    print_instruction_sets();
    std::fflush(stdout);
    // More threads than cores make the runs wait for each other; the spin-then-sleep pool
    // copes, but the seconds columns then measure contention, not the method.
    const unsigned cores = std::thread::hardware_concurrency();
    if (cores > 0 && options_.jobs * options_.threads > static_cast<long>(cores))
      std::cerr << "reproduce: note: --jobs " << options_.jobs << " x --threads "
                << options_.threads << " = " << options_.jobs * options_.threads
                << " threads on " << cores
                << " cores; the timing columns will include the contention\n";
    // Longest first: the best simple schedule for parallel jobs of unequal length.
    std::stable_sort(todo.begin(), todo.end(), [&](const Run* a, const Run* b) {
      return finished_.expected_seconds(*a) > finished_.expected_seconds(*b);
    });
    const int code = loop(todo);
    write_summary();
    if (code == 130) {
      finish_progress();
      const std::size_t kept = finished_.summaries.size();
      std::cerr << "reproduce: interrupted; " << count_of(kept, "run")
                << (kept == 1 ? " is" : " are")
                << " finished and kept; run the same command again to continue\n";
      return code;
    }
    finish_progress();
    std::vector<Summary> rows;
    for (const auto& [key, s] : finished_.summaries) rows.push_back(s);
    print_table(rows);
    std::printf("\nsummary: %s\n", (out_ / "summary.csv").c_str());
    if (!elsewhere_.empty())
      std::printf("reproduce: %s finished by another executor in the same folder (e.g. %s)\n",
                  (count_of(elsewhere_.size(), "run") + (elsewhere_.size() == 1 ? " was" : " were"))
                      .c_str(),
                  elsewhere_.front().c_str());
    if (!failures_.empty()) {
      std::cerr << "reproduce: " << count_of(failures_.size(), "run")
                << " failed and will be redone by the next sweep:\n";
      for (const auto& f : failures_) std::cerr << f;
    }
    // The start-up check saw the folder as it was: a run that another executor of other
    // settings (another --epochs into the same --out) finished meanwhile is no result of this
    // plan, and exit 0 would say that every planned run is.
    if (const auto mismatched = runs_of_other_settings(runs_, plan_); !mismatched.empty()) {
      report_other_settings(runs_, mismatched, true);
      return 1;
    }
    return failures_.empty() ? 0 : 1;
  }

private:
  struct Child {
    const Run* run;
    pid_t pid;
    std::chrono::steady_clock::time_point started;
    FileLock lock;  ///< runs/<name>.lock, held until the run's files are final
  };

  /// Partial training logs and outputs of runs a killed sweep left behind (or of failed runs),
  /// and temporaries of interrupted writes: their runs are redone. A run whose lock another
  /// executor holds is under way there, and its files are left alone.
  void discard_partial_runs() {
    std::map<std::string, std::vector<fs::path>> by_run;
    for (const auto& entry : fs::directory_iterator(runs_)) {
      const std::string file = entry.path().filename().string();
      // The checkpoint of a finished run, or its lock file: a kill between the run's last
      // rename and their removal leaves them.
      std::string run_of;
      for (const std::string_view suffix : {".checkpoint", ".checkpoint.lock"})
        if (file.ends_with(suffix)) run_of = file.substr(0, file.size() - suffix.size());
      if (!run_of.empty() && is_run_name(run_of) && fs::exists(runs_ / (run_of + ".csv"))) {
        remove_or_warn(entry.path());
        continue;
      }
      const auto end = std::min(
          {file.find(".partial."), file.find(".run.tmp."), file.find(".checkpoint.tmp.")});
      if (end != std::string::npos && is_run_name(file.substr(0, end)))
        by_run[file.substr(0, end)].push_back(entry.path());
    }
    std::size_t discarded = 0, resuming = 0, restarting = 0;
    for (const auto& [name, files] : by_run) {
      const FileLock lock = try_lock_run(runs_, name);
      if (!lock.held()) continue;
      // A checkpoint continues the training log it was written with (the program cuts it
      // back to its size at the checkpoint), so that log stays.
      const bool finished = fs::exists(runs_ / (name + ".csv"));  // its temporaries alone
      const bool resumable = !finished && fs::exists(runs_ / (name + ".checkpoint"));
      const fs::path kept = runs_ / (name + ".partial.csv");
      bool all_gone = true;
      for (const auto& file : files)
        if (!resumable || file != kept) all_gone = remove_or_warn(file) && all_gone;
      if (!all_gone || finished) continue;  // named above, and again until it goes
      ++discarded;
      // An executor of --run NAME clears every run's leftovers but runs NAME alone; `start`
      // drops a checkpoint of other settings than the plan's.
      const Run* planned = planned_run(name);
      if (planned == nullptr) continue;
      if (resumable && fs::exists(kept) && described_as(*planned)) ++resuming;
      else ++restarting;
    }
    if (discarded > 0)
      std::printf("reproduce: discarded the partial files of %s of an interrupted sweep (one "
                  "that resumes keeps its checkpoint and training log); of those planned here: "
                  "%zu resuming from a checkpoint, %zu starting over\n",
                  count_of(discarded, "unfinished run").c_str(), resuming, restarting);
  }

  /// The run of the plan named `name`, or nullptr.
  [[nodiscard]] const Run* planned_run(const std::string& name) const {
    for (const Run& run : plan_)
      if (run.name() == name) return &run;
    return nullptr;
  }

  /// Whether the run folder's description of `run`'s name is `run`'s.
  [[nodiscard]] bool described_as(const Run& run) const {
    return read_text(run_file(runs_, run, ".run")) == run.description();
  }

  /// Finished runs whose files do not hold together (finished_run.hpp): named, set aside in
  /// runs/damaged/, and, when planned, redone.
  void forget_damaged() {
    std::set<std::string> planned;
    for (const Run& run : plan_) planned.insert(run.name());
    for (const auto& [name, why] : scan_finished(runs_).damaged) {
      // Under the run's lock, and only while still damaged: another executor that set it
      // aside first may be running it again, its fresh files in place.
      const FileLock lock = try_lock_run(runs_, name);
      if (lock.busy() || !scan_finished(runs_).damaged.contains(name)) continue;
      const std::string kept = set_aside_damaged(runs_, name);
      if (planned.contains(name))
        std::printf("reproduce: %s: %s; the run is redone, %s\n", name.c_str(), why.c_str(),
                    kept.c_str());
      else
        warn_unplanned_damage(name, why, concat("; ", kept,
                                                "; a sweep that plans it redoes it"));
    }
  }

  void write_summary() { finished_ = rebuild_summary(out_); }

  /// Removes the run's checkpoint and the lock file its task program held on it (no program
  /// runs the run: this executor holds the run's lock); whether there was a checkpoint.
  bool remove_checkpoint(const Run& run) const {
    remove_or_warn(run_file(runs_, run, ".checkpoint.lock"));
    return remove_or_warn(run_file(runs_, run, ".checkpoint"));
  }

  /// Starts the run unless another executor holds its lock (the run waits in `waiting_` until
  /// it lets go) or finished it meanwhile.
  bool start(const Run& run) {
    const std::string name = run.name();
    FileLock lock = try_lock_run(runs_, name);
    if (!lock.held()) {
      // Only a lock another process holds is waited for: on a file system without locks
      // (Lustre mounted without flock) every run would wait for ever.
      if (!lock.busy() && lock.error() != EINTR)
        throw sbptt::IoError(concat("cannot lock '", (runs_ / (name + ".lock")).string(), "': ",
                                    std::strerror(lock.error()), "; the runner needs a file "
                                    "system with file locks (flock) to share a folder safely"));
      waiting_.push_back(&run);
      return false;
    }
    if (fs::exists(run_file(runs_, run, ".csv"))) {
      elsewhere_.push_back(name);
      ++done_;
      return false;
    }
    // A checkpoint resumes only the run it was written for (--epochs aside, the programs
    // refuse others): one left by a run of other settings under this name goes. Without a
    // checkpoint the run starts over, and so does its training log. A file that cannot be
    // read or written fails this run alone; one that cannot be removed is named, and the task
    // program then fails on the log it cannot replace.
    try {
      if (!described_as(run)) remove_checkpoint(run);
      if (!fs::exists(run_file(runs_, run, ".checkpoint")))
        remove_or_warn(run_file(runs_, run, ".partial.csv"));
      sbptt::write_file_atomically(run_file(runs_, run, ".run").string(), run.description());
    } catch (const fs::filesystem_error& e) {
      return fail_to_start(name, concat(e.path1(), ": ", e.code().message()));
    } catch (const sbptt::IoError& e) {
      return fail_to_start(name, e.what());
    }
    const auto argv = command_line(run, bin_dir_, runs_, options_.threads);
    // Like the CSV, the log gets its final name only when the run has finished.
    const fs::path log = run_file(runs_, run, ".partial.log");
    const int log_fd = sbptt::detail::open_above_standard_streams(
        log.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (log_fd < 0) {
      const int open_error = errno;
      return fail_to_start(name, concat("cannot write '", log.string(), "': ",
                                        std::strerror(open_error)));
    }
    std::string command = "#";
    for (const auto& a : argv) command += " " + a;
    command += "\n";
    [[maybe_unused]] const auto written = ::write(log_fd, command.data(), command.size());
    const pid_t pid = spawn(argv, log_fd);
    const int spawn_error = errno;
    ::close(log_fd);
    if (pid < 0) return fail_to_start(name, concat("fork failed: ", std::strerror(spawn_error)));
    running_.push_back({&run, pid, std::chrono::steady_clock::now(), std::move(lock)});
    return true;
  }

  /// Records that run `name` could not start, and why; false, for `start` to return.
  bool fail_to_start(const std::string& name, const std::string& why) {
    failures_.push_back(concat("  ", name, ": ", why, "\n"));
    if (!tty_) std::cerr << "reproduce: " << name << " failed: " << why << "\n";
    return false;
  }

  /// A child ended: keep its log as a finished run, or record the failure.
  void finished(const Child& child, int status) {
    const Run& run = *child.run;
    const std::string name = run.name();
    const fs::path partial = run_file(runs_, run, ".partial.csv");
    const fs::path csv = run_file(runs_, run, ".csv");
    const fs::path partial_log = run_file(runs_, run, ".partial.log");
    // for retuning the profiles and the estimates: the whole run, start-up and evaluation
    const double wall =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - child.started).count();
    {
      std::ofstream(partial_log, std::ios::app) << "# reproduce: " << describe_status(status)
                                                << " after " << wall << " s wall time\n";
    }
    std::string failure;
    if (WIFEXITED(status) && (WEXITSTATUS(status) == 0 || WEXITSTATUS(status) == 3)) {
      const int code = WEXITSTATUS(status);
      // Stopped in the first epoch: no row was logged, which is the result.
      if (code == 3 && !fs::exists(partial)) sbptt::TrainingLog().save(partial.string());
      try {
        if (!fs::exists(partial))
          throw sbptt::ParseError(concat("exited 0 but wrote no training log ", partial.string()));
        Summary summary = summarize(run, partial);
        failure = contradiction(summary, code);
        if (failure.empty()) {
          // The log first: a crash between the two renames leaves a run to redo, never a
          // finished run whose log the next sweep would discard as partial. The run is
          // finished exactly when its CSV has its name, on disk.
          rename_durably(partial_log, run_file(runs_, run, ".log"));
          rename_durably(partial, csv);
          remove_checkpoint(run);  // served its purpose
          ++done_;
          measured_seconds_ += wall;
          measured_estimate_ += finished_.expected_seconds(run);
          write_summary();
          return;
        }
      } catch (const sbptt::ParseError& e) {
        failure = e.what();
      }
    } else if (const int signal = stopping_signal(status); signal != 0) {
      // A run stopped by a signal keeps its checkpoint, whether killed by it or ended on it.
      if (interrupted) return;  // we stopped it, or Slurm's scancel stopped us both
      const bool killed = WIFSIGNALED(status);
      failure = concat(killed ? "killed" : "stopped", " by signal ", signal, " (",
                       strsignal(signal), killed ? ")" : "); its checkpoint is kept");
    } else if (WIFEXITED(status)) {
      const int code = WEXITSTATUS(status);
      failure = code == 2   ? "exit code 2 (bad flags, or a checkpoint of other settings)"
                : code == 127 ? "exit code 127 (could not execute the program)"
                              : concat("exit code ", code);
      // The program failed, perhaps on its checkpoint (refused, or its log cut): the next
      // attempt starts over.
      if (remove_checkpoint(run))
        failure += "; its checkpoint was removed, the next sweep redoes it from epoch 1";
    }
    failures_.push_back(concat("  ", name, ": ", failure, "; log ", partial_log.string(),
                               ":\n", tail_of(partial_log, 3)));
    if (!tty_) std::cerr << "reproduce: " << name << " failed: " << failure << "\n";
  }

  int loop(const std::vector<const Run*>& todo) {
    tty_ = ::isatty(2) != 0;
    total_ = plan_.size();
    done_ = plan_.size() - todo.size();
    started_ = std::chrono::steady_clock::now();
    queued_ = &todo;
    std::size_t& next = next_;
    auto last_progress = std::chrono::steady_clock::time_point{};
    auto last_retry = std::chrono::steady_clock::now();
    std::chrono::steady_clock::duration quiet_interval = std::chrono::seconds(10);
    while (true) {
      if (interrupted) {
        // On SIGTERM a task program ends its epoch and keeps it in its checkpoint, which may
        // take minutes in a large scene: killed 3 s later, a run lost that epoch. A second
        // signal (Ctrl-C again; Slurm's SIGKILL needs none) kills them at once.
        for (const auto& c : running_) ::kill(c.pid, SIGTERM);
        if (!running_.empty()) {
          finish_progress();
          std::cerr << "reproduce: " << sbptt::signal_name(interrupted) << ": stopping "
                    << count_of(running_.size(), "running run")
                    << " after the current epoch, which keeps its work; a second signal "
                       "kills them at once\n";
        }
        bool killed = false;
        while (!running_.empty()) {
          reap();
          if (!killed && signals_received > 1) {
            for (const auto& c : running_) ::kill(c.pid, SIGKILL);
            killed = true;
          }
          std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
        return 130;
      }
      bool changed = false;
      const auto free_slot = [&] {
        return running_.size() < static_cast<std::size_t>(options_.jobs);
      };
      while (free_slot() && next < todo.size()) {
        start(*todo[next++]);
        changed = true;
      }
      // Exit 0 says every planned run is finished: a run that another executor holds is
      // waited for, and run here if that executor lets go of it unfinished (killed, failed).
      auto now = std::chrono::steady_clock::now();
      if (next == todo.size() && free_slot() && !waiting_.empty() &&
          now - last_retry > std::chrono::seconds(1)) {
        const std::vector<const Run*> waited = std::exchange(waiting_, {});
        for (const Run* run : waited)
          if (free_slot()) start(*run);
          else waiting_.push_back(run);
        changed = changed || waiting_.size() != waited.size();
        last_retry = now;
      }
      if (running_.empty() && waiting_.empty()) break;
      changed = reap() || changed;
      now = std::chrono::steady_clock::now();
      // A log (not a terminal) gets a line when something changed, and, while the sweep waits
      // for runs held elsewhere, again after 10 s, 20 s, ... up to every 10 minutes.
      if (changed) quiet_interval = std::chrono::seconds(10);
      const bool quiet_too_long = !waiting_.empty() && now - last_progress > quiet_interval;
      if ((tty_ && now - last_progress > std::chrono::milliseconds(500)) ||
          (!tty_ && (changed || quiet_too_long))) {
        progress();
        last_progress = now;
        if (!changed) quiet_interval = std::min<std::chrono::steady_clock::duration>(
            2 * quiet_interval, std::chrono::minutes(10));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return 0;
  }

  /// Collects every ended child; true when one ended.
  bool reap() {
    bool any = false;
    for (auto it = running_.begin(); it != running_.end();) {
      int status = 0;
      const pid_t pid = ::waitpid(it->pid, &status, WNOHANG);
      if (pid == it->pid) {
        const Child child = std::move(*it);
        it = running_.erase(it);
        finished(child, status);
        any = true;
      } else {
        ++it;
      }
    }
    return any;
  }

  /// Seconds of wall time left: the expected time of the queued runs and the rest of the
  /// running ones, scaled by how long the runs finished so far took against their expectation,
  /// spread over --jobs.
  [[nodiscard]] double seconds_left() const {
    const double scale = measured_estimate_ > 0 ? measured_seconds_ / measured_estimate_ : 1.0;
    const auto now = std::chrono::steady_clock::now();
    double left = 0;
    for (std::size_t k = next_; queued_ && k < queued_->size(); ++k)
      left += scale * finished_.expected_seconds(*(*queued_)[k]);
    for (const auto& c : running_)
      left += std::max(0.0, scale * finished_.expected_seconds(*c.run) -
                                std::chrono::duration<double>(now - c.started).count());
    return left / static_cast<double>(options_.jobs);
  }

  /// "[done/total] elapsed, time left; running: names": one updating line on a terminal,
  /// plain lines in a log.
  void progress() {
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count();
    std::string names;
    for (const auto& c : running_) names += (names.empty() ? "" : ", ") + c.run->name();
    std::string line = concat("[", done_, "/", total_, "] ", format_duration(elapsed),
                              " elapsed, about ", format_duration(seconds_left()), " left");
    if (!failures_.empty()) line += concat(", ", failures_.size(), " failed");
    if (!names.empty()) line += "; running: " + names;
    if (!waiting_.empty())
      line += concat("; ", waiting_.size(), " held by another executor (e.g. ",
                     waiting_.front()->name(), log_age(*waiting_.front()), ")");
    if (tty_) {
      winsize size{};
      std::size_t width = 100;
      if (::ioctl(2, TIOCGWINSZ, &size) == 0 && size.ws_col > 10) width = size.ws_col;
      if (line.size() >= width) line = line.substr(0, width - 4) + "...";  // the names shortened
      std::fprintf(stderr, "\r%s\033[K", line.c_str());
      progress_shown_ = true;
    } else {
      std::fprintf(stderr, "%s\n", line.c_str());
    }
    std::fflush(stderr);
  }

  /// ", its log last written 2h05m ago" from the newer of the run's partial log and training
  /// log, which the holder keeps writing while it runs: a stopped holder (a suspended job) is
  /// one whose age only grows. Empty when neither is there.
  [[nodiscard]] std::string log_age(const Run& run) const {
    std::optional<fs::file_time_type> newest;
    for (const char* suffix : {".partial.log", ".partial.csv"}) {
      std::error_code error;
      const auto written = fs::last_write_time(run_file(runs_, run, suffix), error);
      if (!error && (!newest || written > *newest)) newest = written;
    }
    if (!newest) return {};
    const double age =
        std::chrono::duration<double>(fs::file_time_type::clock::now() - *newest).count();
    return concat(", its log last written ", format_duration(age), " ago");
  }

  void finish_progress() {
    if (tty_ && progress_shown_) {
      progress();
      std::fprintf(stderr, "\n");
      progress_shown_ = false;
    }
  }

  const Options& options_;
  std::vector<Run> plan_;
  fs::path bin_dir_, out_, runs_;
  FinishedRuns finished_;              ///< on disk, as of the last summary.csv
  std::vector<std::string> failures_;
  std::vector<std::string> elsewhere_;     ///< planned runs another executor finished
  std::vector<const Run*> waiting_;        ///< planned runs another executor holds now
  double measured_seconds_ = 0, measured_estimate_ = 0;  ///< of the runs finished here
  std::vector<Child> running_;
  std::size_t done_ = 0, total_ = 0;
  const std::vector<const Run*>* queued_ = nullptr;  ///< the runs to do, in order
  std::size_t next_ = 0;                              ///< the next of them to start
  bool tty_ = false, progress_shown_ = false;
  std::chrono::steady_clock::time_point started_;
};

}  // namespace reproduce
