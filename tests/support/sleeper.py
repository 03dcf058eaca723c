"""A stand-in child process for launcher tests: ignores its arguments, says it is up, and sleeps."""

import time

if __name__ == "__main__":
    print("sleeping", flush=True)   # past the interpreter's start-up: a SIGINT now is a KeyboardInterrupt
    time.sleep(60)
