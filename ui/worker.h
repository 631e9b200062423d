#pragma once
/// Runs a controller (or any job) on a worker thread and reports back on the
/// GUI thread through Qt signals. The job gets the progress callback and the
/// cancel flag that every controller takes.

#include <QObject>
#include <QString>
#include <QThread>
#include <atomic>
#include <functional>
#include <string>

#include "controllers/controller.h"

namespace arpos::ui {

class Worker : public QObject {
  Q_OBJECT
 public:
  using Job = std::function<std::string(const ControllerCallbacks&)>;
  explicit Worker(QObject* parent = nullptr);
  ~Worker() override;
  /// Starts `job` unless one is running; returns false if busy.
  bool Start(Job job);
  /// The same, and calls `done` once, on `receiver`'s thread, when this job
  /// finishes (ok: the job returned; message: its result or the error).
  bool Start(Job job, QObject* receiver, std::function<void(bool ok, QString message)> done);
  void Cancel() { cancel_ = true; }
  bool busy() const { return busy_; }

 signals:
  void Progress(QString step, double fraction);
  /// ok: the job returned; message is its return value or the error text.
  void Finished(bool ok, QString message);

 private:
  QThread* thread_ = nullptr;
  std::atomic<bool> cancel_{false};
  std::atomic<bool> busy_{false};
};

}  // namespace arpos::ui
