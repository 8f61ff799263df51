"""The person panel in a real browser: opened from the map or the people list, closed with Escape."""

from __future__ import annotations

from tests.dashboard.cdp import Page


def test_clicking_a_person_on_the_map_shows_trajectory_and_contacts(page: Page) -> None:
    # Person 3 mills about slowly in the entrance, close to person 4: still where it was when clicked.
    # The map draws on the next animation frame after a tick arrives: wait until it has drawn 3.
    point = page.wait_for("window.bevflow.screenOf(3)", what="person 3 on the map")
    page.click_at(point["x"], point["y"])
    page.wait_for("document.getElementById('person-panel').dataset.loaded === 'true'", what="the person panel")
    assert page.evaluate("document.getElementById('person-title').textContent") == "Person #3"
    assert page.evaluate("window.bevflow.selected") == 3
    assert page.evaluate("window.bevflow.trajectory") >= 50  # a minute of history, about one point a second
    assert page.evaluate("document.querySelector('#contacts-body tr[data-track=\"4\"]') !== null")
    assert page.evaluate("document.querySelector('#people-list [data-track=\"3\"]').getAttribute('aria-pressed')") == "true"
    # A contact is a link to that person.
    # A contact lost and found again under several ids has a button for each: take #4's.
    # The table is rebuilt every 2 s with fresh durations: a click that lands mid-redraw is clicked again.
    page.click_until("#contacts-body button[data-track='4']",
                     "document.getElementById('person-title').textContent === 'Person #4'", what="the contact's panel")


def test_people_list_opens_a_person_from_the_keyboard_and_escape_closes(page: Page) -> None:
    page.evaluate("document.querySelector('#people-list [data-track=\"5\"]').focus()")
    page.press("Enter", text="\r")
    page.wait_for("document.getElementById('person-panel').dataset.loaded === 'true'", what="the person panel")
    assert page.evaluate("document.getElementById('person-title').textContent") == "Person #5"
    assert page.evaluate("document.activeElement.id") == "person-close"
    page.press("Escape")
    page.wait_for("document.getElementById('person-panel').hidden", what="the panel to close")
    assert page.evaluate("window.bevflow.selected") is None
    assert page.evaluate("document.activeElement.dataset.track") == "5"  # focus back where it was
