"""LifecycleClient.change_state survives a lost request or a lost answer (a service race under load)."""

import threading

import pytest
from rclpy.task import Future

from ppod_ros.errors import DeviceError

pytestmark = [pytest.mark.ros]


class FakeNode:
    """The far side: a lifecycle state that a delivered request changes, and a network that loses."""

    def __init__(self, lose_requests=0, lose_answers=0, slow_attempts=0):
        self.state = "unconfigured"
        self.lose_requests = lose_requests
        self.lose_answers = lose_answers
        self.slow_attempts = slow_attempts
        self.requests = 0

    def handle(self, transition_id):
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import ChangeState

        self.requests += 1
        future = Future()
        if self.lose_requests:
            self.lose_requests -= 1
            return future  # never arrives, never answered
        if self.slow_attempts:
            self.slow_attempts -= 1
            self.state = "configuring"
            return future  # at work past the attempt window; get_state says so
        ok = self.state == "unconfigured" and transition_id == Transition.TRANSITION_CONFIGURE
        if ok or self.state == "configuring":
            self.state = "inactive"
        if self.lose_answers:
            self.lose_answers -= 1
            return future  # done, but the answer is lost
        future.set_result(ChangeState.Response(success=ok))
        return future


class FakeClient:
    def __init__(self, far):
        self.far = far
        self.removed = 0

    def wait_for_service(self, timeout_sec=None):
        return True

    def call_async(self, req):
        return self.far.handle(req.transition.id)

    def remove_pending_request(self, future):
        self.removed += 1


@pytest.fixture
def make_client():
    from ppod_nodes.launch.lifecycle_client import LifecycleClient

    made = []

    def make(far):
        lc = LifecycleClient("lifecycle_client_test")
        made.append(lc)
        fake = FakeClient(far)
        lc._client = lambda node, kind: fake
        lc.get_state = lambda node, timeout_s=5.0: far.state
        return lc, fake

    yield make
    for lc in made:
        lc.close()


def test_a_lost_request_is_sent_again(make_client):
    far = FakeNode(lose_requests=2)
    lc, _ = make_client(far)
    assert lc.change_state("n", "configure", timeout_s=5, attempt_s=0.05)
    assert far.requests == 3 and far.state == "inactive"


def test_a_lost_answer_is_read_from_the_state(make_client):
    far = FakeNode(lose_answers=1)
    lc, fake = make_client(far)
    assert lc.change_state("n", "configure", timeout_s=5, attempt_s=0.05)
    assert far.requests == 1 and fake.removed == 1


def test_a_slow_transition_is_waited_for_not_repeated(make_client):
    far = FakeNode(slow_attempts=1)
    lc, _ = make_client(far)
    # The node reports "configuring" during the attempt, then the state settles: no second request.
    threading.Timer(0.2, lambda: setattr(far, "state", "inactive")).start()
    assert lc.change_state("n", "configure", timeout_s=5, attempt_s=0.05)
    assert far.requests == 1


def test_a_refused_transition_is_false_and_silence_is_an_error(make_client):
    far = FakeNode()
    far.state = "active"
    lc, _ = make_client(far)
    assert not lc.change_state("n", "configure", timeout_s=5, attempt_s=0.05)
    far2 = FakeNode(lose_requests=10**6)
    lc2, _ = make_client(far2)
    with pytest.raises(DeviceError, match="no answer within 0.3 s"):
        lc2.change_state("n", "configure", timeout_s=0.3, attempt_s=0.05)
