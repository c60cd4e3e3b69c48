from trackcli.cli.commands import main

main()
