#include "ui/worker.h"

namespace arpos::ui {

Worker::Worker(QObject* parent) : QObject(parent) {}

Worker::~Worker() {
  cancel_ = true;
  if (thread_) {
    thread_->wait();
    delete thread_;
  }
}

bool Worker::Start(Job job) {
  if (busy_) return false;
  if (thread_) {
    thread_->wait();
    delete thread_;
  }
  busy_ = true;
  cancel_ = false;
  thread_ = QThread::create([this, job = std::move(job)] {
    ControllerCallbacks callbacks;
    callbacks.progress = [this](const std::string& step, double fraction) {
      emit Progress(QString::fromStdString(step), fraction);
    };
    callbacks.cancel_requested = [this] { return cancel_.load(); };
    bool ok = true;
    QString message;
    try {
      message = QString::fromStdString(job(callbacks));
    } catch (const std::exception& e) {
      ok = false;
      message = QString::fromStdString(e.what());
    }
    busy_ = false;
    emit Finished(ok, message);
  });
  thread_->start();
  return true;
}

}  // namespace arpos::ui
