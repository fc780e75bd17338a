"""The administrator's screens and the clinical-data edit, driven as a user would on a real
SQLite record: the first administrator on an empty database, the Users page (create with a
role, change a role, deactivate, reset a password; every change audited, the admin's own
account protected), the patient's clinical data edited by a clinician (audited, refused over
someone else's change, read-only for other roles)."""
from __future__ import annotations

import gui_support  # noqa: F401  (offscreen platform before Qt)
import pytest
from patients_helpers import PASSWORD, open_record, staff
from PySide6.QtCore import Qt

from app.main_window import MainWindow
from app.settings import GuiSettings
from patients.errors import AuthenticationFailed

WAIT_MS = 15_000


@pytest.fixture()
def empty_record(tmp_path):
    rec = open_record(str(tmp_path / "talus.db"))
    yield rec
    rec.close()


def _window(qtbot, record, tmp_path) -> MainWindow:
    w = MainWindow(None, GuiSettings(recordings_dir=str(tmp_path)), record=record)
    qtbot.addWidget(w)
    w.show()
    return w


def _login(window, qtbot, user: str, password: str = PASSWORD) -> None:
    page = window.login
    page.user.setText(user)
    page.password.setText(password)
    qtbot.mouseClick(page.button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: window.actor is not None, timeout=WAIT_MS)


def _audit_actions(record, admin) -> list[tuple[str, str | None]]:
    return [(e["action"], e.get("entity_key")) for e in record.export_audit(admin)]


def test_first_administrator_is_created_on_an_empty_database(qtbot, empty_record, tmp_path):
    window = _window(qtbot, empty_record, tmp_path)
    page = window.login
    qtbot.waitUntil(lambda: page.first_admin, timeout=WAIT_MS)
    assert page.password2.isVisible() and "first administrator" in page.title.text()
    page.user.setText("root")
    page.password.setText(PASSWORD)
    page.password2.setText(PASSWORD + "x")
    qtbot.mouseClick(page.button, Qt.MouseButton.LeftButton)
    assert "differ" in page.message.text()
    assert not empty_record.has_users()                     # refused: nothing created
    page.password.setText("short")
    page.password2.setText("short")
    qtbot.mouseClick(page.button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "at least" in page.message.text(), timeout=WAIT_MS)
    assert not empty_record.has_users() and page.first_admin
    page.password.setText(PASSWORD)
    page.password2.setText(PASSWORD)
    qtbot.mouseClick(page.button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: window.actor is not None, timeout=WAIT_MS)
    assert window.actor.username == "root" and window.actor.role.value == "admin"
    assert not page.first_admin and not page.password2.isVisible()
    assert window.rail_buttons["users"].isVisible()
    # a second window on the same database logs in: the setup is offered once only
    other = _window(qtbot, empty_record, tmp_path)
    qtbot.waitUntil(lambda: other.login.checked_users, timeout=WAIT_MS)
    assert not other.login.first_admin


def test_admin_manages_users_and_every_change_is_audited(qtbot, empty_record, tmp_path):
    people = staff(empty_record)
    window = _window(qtbot, empty_record, tmp_path)
    _login(window, qtbot, "admin")
    assert window.rail_buttons["users"].isVisible()
    qtbot.mouseClick(window.rail_buttons["users"], Qt.MouseButton.LeftButton)
    page = window.users
    qtbot.waitUntil(lambda: page.list.count() == 4, timeout=WAIT_MS)

    # create bea, a clinician (passwords typed twice)
    page.new_name.setText("bea")
    page.new_role.setCurrentIndex(page.new_role.findData("clinician"))
    page.new_password.setText(PASSWORD)
    page.new_password2.setText(PASSWORD)
    qtbot.mouseClick(page.create_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: page.list.count() == 5 and page.chosen() is not None
                    and page.chosen()["username"] == "bea", timeout=WAIT_MS)
    assert empty_record.authenticate("bea", PASSWORD).role.value == "clinician"
    # a duplicate is refused with the record's words, nothing added
    page.new_name.setText("bea")
    page.new_password.setText(PASSWORD)
    page.new_password2.setText(PASSWORD)
    qtbot.mouseClick(page.create_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "exists" in page.message.text(), timeout=WAIT_MS)
    assert len(empty_record.list_users(people.admin)) == 5

    # bea becomes a viewer
    page.role.setCurrentIndex(page.role.findData("viewer"))
    qtbot.mouseClick(page.role_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "Role of bea changed" in page.message.text(), timeout=WAIT_MS)
    assert empty_record.authenticate("bea", PASSWORD).role.value == "viewer"

    # deactivated: bea can no longer log in; reactivated with a new password: she can
    assert page.disable_button.text() == "Deactivate"
    qtbot.mouseClick(page.disable_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: page.chosen() is not None and page.chosen()["disabled"],
                    timeout=WAIT_MS)
    with pytest.raises(AuthenticationFailed):
        empty_record.authenticate("bea", PASSWORD)
    assert page.disable_button.text() == "Reactivate"
    qtbot.mouseClick(page.disable_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: page.chosen() is not None and not page.chosen()["disabled"],
                    timeout=WAIT_MS)
    page.reset_password.setText("a new long password")
    page.reset_password2.setText("a new long password")
    qtbot.mouseClick(page.reset_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "Password of bea reset" in page.message.text(), timeout=WAIT_MS)
    assert empty_record.authenticate("bea", "a new long password").username == "bea"
    assert page.reset_password.text() == ""                   # never left on screen

    actions = _audit_actions(empty_record, people.admin)
    for expected in (("user.create", "bea"), ("user.role", "bea"), ("user.disable", "bea"),
                     ("user.enable", "bea"), ("user.passwd", "bea")):
        assert expected in actions

    # the admin's own account: role and deactivation not offered (and refused by the record)
    for i in range(page.list.count()):
        if page.list.item(i).data(Qt.ItemDataRole.UserRole) == "admin":
            page.list.setCurrentRow(i)
    assert not page.role_button.isEnabled() and not page.disable_button.isEnabled()
    from patients.user_roles import set_user_role
    with pytest.raises(Exception, match="own role"):
        set_user_role(empty_record, window.actor, "admin", "viewer")


def test_roles_change_only_by_another_admin_and_others_see_no_users_page(qtbot, empty_record,
                                                                         tmp_path):
    people = staff(empty_record)
    from patients.errors import PermissionDenied
    from patients.user_roles import set_user_role
    from rt.errors import InputError

    empty_record.add_user(people.admin, "boss", "admin", PASSWORD)
    boss = empty_record.authenticate("boss", PASSWORD)
    with pytest.raises(PermissionDenied):
        set_user_role(empty_record, people.clinician, "viewer", "admin")  # not an admin
    with pytest.raises(InputError, match="own role"):                   # an admin remains
        set_user_role(empty_record, boss, "boss", "viewer")
    with pytest.raises(InputError, match="role"):
        set_user_role(empty_record, boss, "viewer", "superuser")
    assert set_user_role(empty_record, boss, "admin", "clinician")["role"] == "clinician"
    roles = {u["username"]: u["role"] for u in empty_record.list_users(boss)}
    assert roles == {"admin": "clinician", "boss": "admin", "clinician": "clinician",
                     "engineer": "engineer", "viewer": "viewer"}

    window = _window(qtbot, empty_record, tmp_path)
    _login(window, qtbot, "viewer")
    assert not window.rail_buttons["users"].isVisible()


def test_clinician_edits_clinical_data_audited_and_refused_over_a_concurrent_change(
        qtbot, empty_record, tmp_path):
    people = staff(empty_record)
    code = empty_record.add_patient(people.clinician, "P-0007", body_mass_kg=70,
                                    affected_side="right", diagnosis="sprain")["code"]
    window = _window(qtbot, empty_record, tmp_path)
    _login(window, qtbot, "clinician")
    page = window.patients
    qtbot.waitUntil(lambda: page.list.count() == 1, timeout=WAIT_MS)
    page.list.setCurrentRow(0)
    qtbot.waitUntil(lambda: page.current is not None, timeout=WAIT_MS)
    assert page.edit_mass.text() == "70" and page.clinical_button.isEnabled()

    page.edit_mass.setText("72,5")
    page.edit_height.setText("178")
    page.edit_side.setCurrentIndex(page.edit_side.findData("left"))
    page.edit_diagnosis.setText("chronic ankle instability")
    page.edit_notes.setText("uses a brace")
    qtbot.mouseClick(page.clinical_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "Clinical data saved" in page.message.text(), timeout=WAIT_MS)
    p = empty_record.get_patient(people.clinician, code)
    assert (p["body_mass_kg"], p["height_m"], p["affected_side"], p["diagnosis"],
            p["notes"]) == (72.5, pytest.approx(1.78), "left", "chronic ankle instability",
                            "uses a brace")
    qtbot.waitUntil(lambda: "72.5 kg" in page.card.text() and "178 cm" in page.card.text(),
                    timeout=WAIT_MS)
    assert ("patient.update", code) in _audit_actions(empty_record, people.admin)

    # a bad number is refused before anything is sent
    page.edit_mass.setText("heavy")
    qtbot.mouseClick(page.clinical_button, Qt.MouseButton.LeftButton)
    assert "a number is needed" in page.message.text()
    # someone else saves in between: this edit is refused and changes nothing
    page.edit_mass.setText("90")
    empty_record.update_patient(people.clinician, code, body_mass_kg=74)
    qtbot.mouseClick(page.clinical_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "someone else" in page.message.text(), timeout=WAIT_MS)
    assert empty_record.get_patient(people.clinician, code)["body_mass_kg"] == 74
    # out of range: the record's message, nothing changed
    page.open(code)
    qtbot.waitUntil(lambda: page.edit_mass.text() == "74", timeout=WAIT_MS)
    page.edit_mass.setText("900")
    qtbot.mouseClick(page.clinical_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "outside 2..400 kg" in page.message.text(), timeout=WAIT_MS)
    assert empty_record.get_patient(people.clinician, code)["body_mass_kg"] == 74

    # a viewer reads the data but cannot edit them
    window.lock("bye")
    _login(window, qtbot, "viewer")
    qtbot.waitUntil(lambda: page.list.count() == 1, timeout=WAIT_MS)
    page.list.setCurrentRow(0)
    qtbot.waitUntil(lambda: page.current is not None, timeout=WAIT_MS)
    assert not page.clinical_button.isEnabled() and not page.edit_mass.isEnabled()
