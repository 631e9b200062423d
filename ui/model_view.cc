#include "ui/model_view.h"

#include <QVTKOpenGLNativeWidget.h>
#include <vtkActor.h>
#include <vtkAxesActor.h>
#include <vtkCallbackCommand.h>
#include <vtkCamera.h>
#include <vtkCellArray.h>
#include <vtkCellPicker.h>
#include <vtkGenericOpenGLRenderWindow.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataMapper.h>
#include <vtkPolyDataNormals.h>
#include <vtkProperty.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkRenderer.h>
#include <vtkSmartPointer.h>
#include <vtkUnsignedCharArray.h>
#include <QVBoxLayout>
#include <algorithm>
#include <cmath>
#include <map>

namespace arpos::ui {

struct ModelView::Impl {
  QVTKOpenGLNativeWidget* widget = nullptr;
  vtkNew<vtkGenericOpenGLRenderWindow> window;
  vtkNew<vtkRenderer> renderer;
  std::map<std::string, vtkSmartPointer<vtkActor>> actors;
  std::map<std::string, Rigid3d> room_from_mesh;
  vtkNew<vtkCellPicker> picker;
  vtkNew<vtkCallbackCommand> click;
  vtkSmartPointer<vtkAxesActor> axes;
  /// Up to kViewSamples points of each slot, in the room (ResetCamera).
  std::map<std::string, std::vector<Eigen::Vector3d>> view_samples;
  std::optional<Rigid3d> subject;
  bool framed = false;  ///< framed by ResetCamera, not moved by the user since
  vtkNew<vtkCallbackCommand> interaction;
  static constexpr size_t kViewSamples = 4000;

  void Sample(const std::string& slot, const TriangleMesh& mesh, const Rigid3d& room_from_mesh) {
    std::vector<Eigen::Vector3d>& out = view_samples[slot];
    out.clear();
    const size_t step = std::max<size_t>(1, mesh.vertices.size() / kViewSamples);
    for (size_t i = 0; i < mesh.vertices.size(); i += step) {
      out.push_back(room_from_mesh * mesh.vertices[i].cast<double>());
    }
  }
};

ModelView::ModelView(QWidget* parent) : QWidget(parent), impl_(std::make_unique<Impl>()) {
  auto* layout = new QVBoxLayout(this);
  layout->setContentsMargins(0, 0, 0, 0);
  impl_->widget = new QVTKOpenGLNativeWidget(this);
  impl_->widget->setRenderWindow(impl_->window);
  impl_->window->AddRenderer(impl_->renderer);
  impl_->renderer->SetBackground(0.12, 0.13, 0.16);
  impl_->renderer->SetBackground2(0.30, 0.32, 0.38);
  impl_->renderer->GradientBackgroundOn();
  layout->addWidget(impl_->widget);
  setMinimumSize(320, 240);
  impl_->picker->SetTolerance(0.002);
  impl_->click->SetClientData(this);
  impl_->click->SetCallback([](vtkObject* caller, unsigned long, void* client, void*) {
    auto* interactor = static_cast<vtkRenderWindowInteractor*>(caller);
    if (!interactor->GetShiftKey()) return;  // plain clicks turn the view
    static_cast<ModelView*>(client)->PickAt(interactor->GetEventPosition()[0], interactor->GetEventPosition()[1]);
  });
  impl_->interaction->SetClientData(impl_.get());
  impl_->interaction->SetCallback([](vtkObject*, unsigned long, void* client, void*) {
    static_cast<Impl*>(client)->framed = false;
  });
  if (auto* interactor = impl_->window->GetInteractor()) {
    interactor->AddObserver(vtkCommand::LeftButtonPressEvent, impl_->click, 1.0);
    interactor->AddObserver(vtkCommand::StartInteractionEvent, impl_->interaction);
    interactor->AddObserver(vtkCommand::MouseWheelForwardEvent, impl_->interaction);
    interactor->AddObserver(vtkCommand::MouseWheelBackwardEvent, impl_->interaction);
  }
}

void ModelView::PickAt(int x, int y) {
  impl_->click->SetAbortFlag(1);  // a pick, not the start of a camera turn
  if (!impl_->picker->Pick(x, y, 0, impl_->renderer)) {
    emit PickMissed(QString());
    return;
  }
  vtkActor* actor = impl_->picker->GetActor();
  for (const auto& [slot, a] : impl_->actors) {
    if (a.Get() != actor) continue;
    double p[3];
    impl_->picker->GetPickPosition(p);
    const Eigen::Vector3d room(p[0], p[1], p[2]);
    emit Picked(QString::fromStdString(slot), room, impl_->room_from_mesh[slot].Inverse() * room);
    return;
  }
  emit PickMissed(QString());
}

ModelView::~ModelView() = default;

namespace {
vtkSmartPointer<vtkPolyData> ToPolyData(const TriangleMesh& mesh, const Rigid3d& room_from_model) {
  vtkNew<vtkPoints> points;
  points->SetNumberOfPoints(static_cast<vtkIdType>(mesh.vertices.size()));
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const Eigen::Vector3d p = room_from_model * mesh.vertices[i].cast<double>();
    points->SetPoint(static_cast<vtkIdType>(i), p.x(), p.y(), p.z());
  }
  vtkNew<vtkCellArray> polys;
  for (const auto& f : mesh.faces) {
    const vtkIdType ids[3] = {f[0], f[1], f[2]};
    polys->InsertNextCell(3, ids);
  }
  auto poly = vtkSmartPointer<vtkPolyData>::New();
  poly->SetPoints(points);
  poly->SetPolys(polys);
  return poly;
}
}  // namespace

void ModelView::SetColoredMesh(const std::string& slot, const TriangleMesh& mesh, const Rigid3d& room_from_model,
                               const std::vector<std::array<std::uint8_t, 3>>& vertex_rgb, double opacity) {
  vtkSmartPointer<vtkPolyData> poly = ToPolyData(mesh, room_from_model);
  if (vertex_rgb.size() == mesh.vertices.size()) {
    vtkNew<vtkUnsignedCharArray> colours;
    colours->SetNumberOfComponents(3);
    colours->SetName("colours");
    colours->SetNumberOfTuples(static_cast<vtkIdType>(vertex_rgb.size()));
    for (size_t i = 0; i < vertex_rgb.size(); ++i) {
      for (int c = 0; c < 3; ++c) colours->SetComponent(static_cast<vtkIdType>(i), c, vertex_rgb[i][c]);
    }
    poly->GetPointData()->SetScalars(colours);
  }
  vtkNew<vtkPolyDataNormals> normals;
  normals->SetInputData(poly);
  normals->SplittingOff();
  vtkNew<vtkPolyDataMapper> mapper;
  mapper->SetInputConnection(normals->GetOutputPort());
  mapper->SetColorModeToDirectScalars();
  mapper->ScalarVisibilityOn();
  impl_->room_from_mesh[slot] = room_from_model;
  impl_->Sample(slot, mesh, room_from_model);
  auto& actor = impl_->actors[slot];
  if (actor) impl_->renderer->RemoveActor(actor);
  actor = vtkSmartPointer<vtkActor>::New();
  actor->SetMapper(mapper);
  actor->GetProperty()->SetOpacity(opacity);
  impl_->renderer->AddActor(actor);
  impl_->window->Render();
}

void ModelView::SetPoints(const std::string& slot, const std::vector<Eigen::Vector3d>& points, double r, double g,
                          double b, double radius_m) {
  if (points.empty()) {
    RemoveMesh(slot);
    return;
  }
  TriangleMesh marks;
  const Eigen::Vector3d axes[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  const int faces[8][3] = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  for (const Eigen::Vector3d& p : points) {
    const int base = static_cast<int>(marks.vertices.size());
    for (const auto& a : axes) marks.vertices.push_back((p + radius_m * a).cast<float>());
    for (const auto& f : faces) marks.faces.emplace_back(base + f[0], base + f[1], base + f[2]);
  }
  SetMesh(slot, marks, Rigid3d::Identity(), r, g, b);
}

void ModelView::RemoveMesh(const std::string& slot) {
  auto it = impl_->actors.find(slot);
  if (it == impl_->actors.end()) return;
  impl_->renderer->RemoveActor(it->second);
  impl_->actors.erase(it);
  impl_->room_from_mesh.erase(slot);
  impl_->view_samples.erase(slot);
  impl_->window->Render();
}

void ModelView::SetMesh(const std::string& slot, const TriangleMesh& mesh, const Rigid3d& room_from_model,
                        double r, double g, double b, double opacity) {
  vtkSmartPointer<vtkPolyData> poly = ToPolyData(mesh, room_from_model);
  vtkNew<vtkPolyDataNormals> normals;
  normals->SetInputData(poly);
  normals->SplittingOff();
  vtkNew<vtkPolyDataMapper> mapper;
  mapper->SetInputConnection(normals->GetOutputPort());
  impl_->room_from_mesh[slot] = room_from_model;
  impl_->Sample(slot, mesh, room_from_model);
  auto& actor = impl_->actors[slot];
  if (actor) impl_->renderer->RemoveActor(actor);
  actor = vtkSmartPointer<vtkActor>::New();
  actor->SetMapper(mapper);
  actor->GetProperty()->SetColor(r, g, b);
  actor->GetProperty()->SetOpacity(opacity);
  impl_->renderer->AddActor(actor);
  impl_->window->Render();
}

void ModelView::ClearMeshes() {
  for (auto& [slot, actor] : impl_->actors) impl_->renderer->RemoveActor(actor);
  impl_->actors.clear();
  impl_->room_from_mesh.clear();
  impl_->view_samples.clear();
  impl_->window->Render();
}

void ModelView::ShowRoomAxes(double length_m) {
  if (!impl_->axes) {
    impl_->axes = vtkSmartPointer<vtkAxesActor>::New();
    impl_->renderer->AddActor(impl_->axes);
  }
  impl_->axes->SetTotalLength(length_m, length_m, length_m);
  impl_->axes->SetAxisLabels(0);
}

void ModelView::SetViewSubject(const std::optional<Rigid3d>& room_from_model) {
  impl_->subject = room_from_model;
}

void ModelView::resizeEvent(QResizeEvent* event) {
  QWidget::resizeEvent(event);
  if (impl_->framed) ResetCamera();
}

void ModelView::ResetCamera() {
  impl_->framed = true;
  std::vector<Eigen::Vector3d> points;
  for (const auto& [slot, samples] : impl_->view_samples)
    points.insert(points.end(), samples.begin(), samples.end());
  vtkCamera* camera = impl_->renderer->GetActiveCamera();
  if (points.size() < 3) {
    impl_->renderer->ResetCamera();
    impl_->window->Render();
    return;
  }
  // The view's axes: from the patient's left and above, anterior up; else
  // the camera's present ones.
  Eigen::Vector3d forward, up;
  if (impl_->subject) {
    const Eigen::Matrix3d r = impl_->subject->rotation.toRotationMatrix();
    up = -r.col(1);  // anterior
    const Eigen::Vector3d from = (0.6 * r.col(0) + 0.8 * up).normalized();
    forward = -from;
  } else {
    double p[3], f[3], u[3];
    camera->GetPosition(p);
    camera->GetFocalPoint(f);
    camera->GetViewUp(u);
    forward = Eigen::Vector3d(f[0] - p[0], f[1] - p[1], f[2] - p[2]);
    up = Eigen::Vector3d(u[0], u[1], u[2]);
    if (forward.norm() < 1e-9) forward = -Eigen::Vector3d::UnitZ();
    forward.normalize();
  }
  up = (up - up.dot(forward) * forward);
  if (up.norm() < 1e-6) up = forward.unitOrthogonal();
  up.normalize();
  const Eigen::Vector3d right = forward.cross(up);
  // Robust extent along each axis of the view.
  auto range = [&](const Eigen::Vector3d& axis) {
    std::vector<double> v;
    v.reserve(points.size());
    for (const auto& p : points) v.push_back(axis.dot(p));
    const size_t lo = v.size() / 500, hi = v.size() - 1 - v.size() / 500;
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(lo), v.end());
    const double a = v[lo];
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(hi), v.end());
    return std::make_pair(a, v[hi]);
  };
  const auto [r0, r1] = range(right);
  const auto [u0, u1] = range(up);
  const auto [f0, f1] = range(forward);
  const Eigen::Vector3d centre = 0.5 * ((r0 + r1) * right + (u0 + u1) * up + (f0 + f1) * forward);
  const double half_width = std::max(0.5 * (r1 - r0), 0.05),
               half_height = std::max(0.5 * (u1 - u0), 0.05);
  // The widget's size: the render window's lags behind the layout.
  const double aspect = width() > 0 && height() > 0 ? static_cast<double>(width()) / height() : 1.0;
  const double tan_half = std::tan(0.5 * camera->GetViewAngle() * M_PI / 180.0);
  const double distance =
      1.12 * std::max(half_height / tan_half, half_width / (aspect * tan_half)) + 0.5 * (f1 - f0);
  const Eigen::Vector3d position = centre - distance * forward;
  camera->SetFocalPoint(centre.x(), centre.y(), centre.z());
  camera->SetPosition(position.x(), position.y(), position.z());
  camera->SetViewUp(up.x(), up.y(), up.z());
  impl_->renderer->ResetCameraClippingRange();
  impl_->window->Render();
}

QImage ModelView::Grab() {
  impl_->window->Render();
  return impl_->widget->grabFramebuffer();
}

}  // namespace arpos::ui
